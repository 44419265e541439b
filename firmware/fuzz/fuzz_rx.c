/* libFuzzer harness: the firmware's receive path, from UART bytes to the application.
 *
 * Reached: app_rx (both channels) -> link_rx_byte -> cobs_decode -> CRC check ->
 * acnf_parse_stimulus / acnf_parse_command -> app_sample / app_command, and from there the
 * generated filter, the block and checkpoint packers and link_send. Random bytes almost never
 * carry a valid CRC-32, so the first input byte picks one of two modes:
 *
 *   even: raw mode. The rest goes to app_rx as is (channel: bit 1), and to cobs_decode and the two
 *         parsers directly, at every length.
 *   odd:  structured mode. The rest is a list of operations; the harness frames the fuzzer's
 *         payloads itself (CRC-32 + COBS + delimiter), so mutations land in the parsers and the
 *         application instead of dying at the CRC:
 *           op&3 == 0  frame:  len, payload[len]  -> framed, to channel (op>>2)&1; op&8: CRC
 *                              damaged (the refusal path with an otherwise valid frame)
 *           op&3 == 1  raw:    len, bytes[len]    -> to channel (op>>2)&1 unframed
 *           op&3 == 2  missed: n                  -> app_missed(n) (a slow main loop)
 *           op&3 == 3  burst:  k, stimulus body   -> k + 1 framed stimulus frames (fills blocks
 *                              and reaches checkpoints in a few bytes)
 *
 * Oracle besides ASan/UBSan: every frame the firmware sends (board_uart_write) must be one whole
 * frame: ends in its only zero byte, COBS-decodes, carries a good CRC, a known type and that
 * type's exact size. A violation aborts, so libFuzzer saves the input. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "acn_board.h"
#include "acnframe.h"
#include "app.h"
#include "cobs.h"
#include "crc32.h"
#include "link.h"

/* samples per input (bursts and missed): keeps one input in the millisecond range */
#define FUZZ_MAX_SAMPLES 4096u
/* the largest payload the harness frames: a byte of length, plus the CRC */
#define FUZZ_FRAME_MAX (COBS_MAX_ENCODED(255u + 4u) + 1u)

static unsigned samples_left;

static void fail(const char *what, size_t n)
{
    fprintf(stderr, "fuzz_rx: firmware sent a bad frame (%s, %zu bytes)\n", what, n);
    abort();
}

static size_t expected_size(uint8_t type)
{
    switch (type) {
    case ACNF_T_SAMPLE:
        return ACNF_SAMPLE_SIZE;
    case ACNF_T_INFO:
        return ACNF_INFO_SIZE;
    case ACNF_T_ACK:
        return ACNF_ACK_SIZE;
    case ACNF_T_BLOCK:
        return ACNF_BLOCK_SIZE;
    case ACNF_T_CHECKPOINT:
        return ACNF_CHECKPOINT_SIZE;
    default:
        return 0;
    }
}

/* ---- the board: telemetry is checked and dropped; time and ids are fixed (reproducible) ---- */

void board_init(void) {}

bool board_poll(void)
{
    return false;
}

uint32_t board_time_ms(void)
{
    return 0;
}

uint8_t board_id(void)
{
    return ACNF_BOARD_HOST;
}

uint16_t board_boot_id(void)
{
    return 1u; /* as the host and emulated boards: one power-on per input (app_init) */
}

uint32_t board_rx_lost(void)
{
    return 0;
}

bool board_uart_write(const uint8_t *p, size_t n)
{
    uint8_t raw[ACNF_MAX_UP_WIRE];
    size_t k;
    size_t m;
    uint32_t crc;
    if (n < 2u || n > ACNF_MAX_UP_WIRE || p[n - 1u] != 0u) {
        fail("size or delimiter", n);
    }
    for (k = 0; k + 1u < n; ++k) {
        if (p[k] == 0u) {
            fail("zero inside", n);
        }
    }
    m = cobs_decode(p, n - 1u, raw);
    if (m == COBS_ERROR || m < 5u) {
        fail("COBS", n);
    }
    m -= 4u;
    crc = (uint32_t)raw[m] | (uint32_t)raw[m + 1u] << 8 | (uint32_t)raw[m + 2u] << 16 |
          (uint32_t)raw[m + 3u] << 24;
    if (crc != crc32_update(0u, raw, m)) {
        fail("CRC", n);
    }
    if (expected_size(raw[0]) != m) {
        fail("type or payload size", n);
    }
    return true;
}

/* ---- the harness ---- */

/* CRC-32 LE after the payload, COBS, delimiter: the wire form of a host->MCU frame. */
static size_t frame(const uint8_t *payload, size_t n, bool bad_crc, uint8_t *out)
{
    uint8_t raw[255u + 4u];
    uint32_t crc = crc32_update(0u, payload, n);
    size_t w;
    if (bad_crc) {
        crc ^= 1u;
    }
    memcpy(raw, payload, n);
    raw[n] = (uint8_t)crc;
    raw[n + 1u] = (uint8_t)(crc >> 8);
    raw[n + 2u] = (uint8_t)(crc >> 16);
    raw[n + 3u] = (uint8_t)(crc >> 24);
    w = cobs_encode(raw, n + 4u, out);
    out[w++] = 0u;
    return w;
}

static void raw_mode(uint8_t mode, const uint8_t *p, size_t n)
{
    acnf_command_t c;
    acnf_stimulus_t t;
    uint8_t *copy = malloc(n ? n : 1u); /* exact size: ASan sees any read past the input */
    app_rx((mode >> 1) & 1u, p, n);
    (void)acnf_parse_command(p, n, &c);
    (void)acnf_parse_stimulus(p, n, &t);
    memcpy(copy, p, n);
    (void)cobs_decode(copy, n, copy); /* in place, as link_rx_byte does */
    free(copy);
}

static void structured_mode(const uint8_t *p, size_t n)
{
    uint8_t wire[FUZZ_FRAME_MAX];
    uint8_t stim[ACNF_STIMULUS_SIZE];
    size_t i = 0;
    while (i + 1u < n) {
        uint8_t op = p[i++];
        uint8_t arg = p[i++];
        unsigned ch = (op >> 2) & 1u;
        size_t len = arg;
        switch (op & 3u) {
        case 0:
            len = len < n - i ? len : n - i;
            app_rx(ch, wire, frame(p + i, len, (op & 8u) != 0u, wire));
            i += len;
            break;
        case 1:
            len = len < n - i ? len : n - i;
            app_rx(ch, p + i, len);
            i += len;
            break;
        case 2:
            len = len < samples_left ? len : samples_left;
            samples_left -= (unsigned)len;
            app_missed((uint32_t)len);
            break;
        default: {
            size_t body = ACNF_STIMULUS_SIZE - 1u;
            size_t k;
            size_t w;
            len += 1u;
            len = len < samples_left ? len : samples_left;
            samples_left -= (unsigned)len;
            stim[0] = ACNF_T_STIMULUS;
            memset(stim + 1, 0, body);
            memcpy(stim + 1, p + i, body < n - i ? body : n - i);
            i += body < n - i ? body : n - i;
            w = frame(stim, sizeof stim, false, wire);
            for (k = 0; k < len; ++k) {
                app_rx(ch, wire, w);
            }
            break;
        }
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    app_init(); /* power-on state for every input: runs are reproducible one by one */
    samples_left = FUZZ_MAX_SAMPLES;
    if (size == 0u) {
        return 0;
    }
    if (data[0] & 1u) {
        structured_mode(data + 1, size - 1u);
    } else {
        raw_mode(data[0], data + 1, size - 1u);
    }
    return 0;
}
