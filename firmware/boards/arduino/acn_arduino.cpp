/* The Arduino board layer of acn_arduino.h: the board interface (acn_board.h) on the Arduino core.
 */
#include <Arduino.h>
#include <string.h>

#include "acn_arduino.h"

extern "C" {
#include "acn_board.h"
}

#define WIRE(size) ((size) + 6u) /* CRC 4, COBS code 1, delimiter 1: every frame is < 254 bytes */
#define MAX2(a, b) ((a) > (b) ? (a) : (b))
/* The most telemetry one received byte or one sample can queue: a block and every axis' checkpoint
 * (or a sample frame, or info), then an ack. */
#define TX_NEED                                                                                    \
    (MAX2(MAX2(WIRE(ACNF_BLOCK_SIZE) + ACNF_NAXES * WIRE(ACNF_CHECKPOINT_SIZE),                    \
               WIRE(ACNF_SAMPLE_SIZE)),                                                            \
          WIRE(ACNF_INFO_SIZE)) +                                                                  \
     WIRE(ACNF_ACK_SIZE))
#if TX_NEED <= 256u
#define TX_SIZE 256u
#else
#define TX_SIZE 512u
#endif

static uint8_t tx_ring[TX_SIZE]; /* a power of two: the indices wrap through it */
static uint16_t tx_head, tx_tail;

static uint16_t tx_free(void)
{
    return (uint16_t)(TX_SIZE - (uint16_t)(tx_head - tx_tail));
}

extern "C" bool board_uart_write(const uint8_t *p, size_t n)
{
    size_t i;
    if (n > tx_free()) {
        return false; /* the application counts it (tx_drop): the link is too slow for the rate */
    }
    for (i = 0; i < n; ++i) {
        tx_ring[tx_head++ & (TX_SIZE - 1u)] = p[i];
    }
    return true;
}

extern "C" uint32_t board_time_ms(void)
{
    return millis();
}

extern "C" uint8_t board_id(void)
{
    return ACNF_BOARD_ARDUINO;
}

extern "C" uint16_t board_boot_id(void)
{
    return 1u; /* no counter kept in EEPROM: the value the host board uses too */
}

extern "C" uint32_t board_rx_lost(void)
{
    return 0u; /* the core's serial ring drops what overflows it without a count */
}

void acn_arduino_begin(void)
{
    tx_head = tx_tail = 0;
    app_init();
}

void acn_arduino_sample(const uint16_t *code)
{
    acnf_stimulus_t in;
    unsigned i;
    memset(&in, 0, sizeof in);
    for (i = 0; i < ACNF_NAXES; ++i) {
        in.code[i] = code[i];
    }
    app_sample(&in);
}

void acn_arduino_missed(uint16_t n)
{
    app_missed(n);
}

void acn_arduino_poll(Stream &link)
{
    while (tx_free() >= TX_NEED && link.available() > 0) {
        uint8_t b = (uint8_t)link.read();
        app_rx(APP_CH_HOST, &b, 1);
    }
    while (tx_tail != tx_head && link.availableForWrite() > 0) {
        link.write(tx_ring[tx_tail++ & (TX_SIZE - 1u)]);
    }
}
