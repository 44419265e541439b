/* Host board (POSIX): for software-in-the-loop runs and for fuzzing.
 *
 * As a program (main.c + this file): frames in on stdin (stimulus frames stand
 * in for the ADC, command frames as from the host), telemetry out on stdout;
 * it ends at the end of stdin. Linked into a cffi module instead (no main.c),
 * the telemetry stays in a buffer that board_host_take() empties. */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "acn_board.h"
#include "board_host.h"

#define HOST_TX_CAP 65536u

static uint8_t tx_buf[HOST_TX_CAP];
static size_t tx_len;
static size_t tx_limit = HOST_TX_CAP;
static struct timespec t0;

void board_init(void)
{
    tx_len = 0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
}

uint8_t board_id(void)
{
    return ACNF_BOARD_HOST;
}

static uint16_t boot_id = 1u;

uint16_t board_boot_id(void)
{
    return boot_id; /* 1, as on the emulated boards, unless a test simulates another power-on */
}

void board_host_set_boot_id(uint16_t id)
{
    boot_id = id;
}

uint32_t board_rx_lost(void)
{
    return 0; /* stdin and the in-process buffer lose nothing */
}

uint32_t board_time_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (uint32_t)((t.tv_sec - t0.tv_sec) * 1000 + (t.tv_nsec - t0.tv_nsec) / 1000000);
}

bool board_uart_write(const uint8_t *p, size_t n)
{
    if (n > tx_limit - tx_len) {
        return false;
    }
    memcpy(tx_buf + tx_len, p, n);
    tx_len += n;
    return true;
}

size_t board_host_take(uint8_t *out, size_t max)
{
    size_t n = tx_len < max ? tx_len : max;
    memcpy(out, tx_buf, n);
    memmove(tx_buf, tx_buf + n, tx_len - n);
    tx_len -= n;
    return n;
}

void board_host_set_tx_limit(size_t limit)
{
    tx_limit = limit < HOST_TX_CAP ? limit : HOST_TX_CAP;
}

static bool flush_stdout(void)
{
    size_t done = 0;
    while (done < tx_len) {
        ssize_t w = write(1, tx_buf + done, tx_len - done);
        if (w < 0 && errno == EINTR) {
            continue;
        }
        if (w <= 0) {
            return false;
        }
        done += (size_t)w;
    }
    tx_len = 0;
    return true;
}

bool board_poll(void)
{
    uint8_t buf[4096];
    ssize_t n = read(0, buf, sizeof buf);
    if (n < 0 && errno == EINTR) {
        return true;
    }
    if (n <= 0) {
        return false;
    }
    /* one channel: stimulus and command frames are told apart by their type */
    app_rx(APP_CH_HOST, buf, (size_t)n);
    return flush_stdout();
}
