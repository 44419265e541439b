/* Framing on a byte link: frame = COBS(payload || CRC-32 LE) || 0x00.
 *
 * Sending: link_send() appends the CRC, encodes and hands the whole frame to
 * board_uart_write() (all or nothing). Receiving: link_rx_byte() takes one
 * byte at a time into a fixed buffer; it never writes past the buffer: an
 * over-long frame is dropped up to its next delimiter, and a frame whose COBS
 * or CRC is wrong is dropped and counted. */
#ifndef ACN_LINK_H
#define ACN_LINK_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "acnframe.h"

/* Longest accepted encoded frame (no delimiter): the largest host->MCU payload, its CRC, one code
 * byte. */
#define LINK_RX_MAX (ACNF_MAX_DOWN_SIZE + 4u + 1u)

typedef struct {
    uint8_t buf[LINK_RX_MAX];
    size_t len;
    bool overlong;   /* more than LINK_RX_MAX bytes since the last delimiter */
    uint32_t errors; /* frames refused (too long, bad COBS, too short, bad CRC) */
} link_rx_t;

void link_rx_init(link_rx_t *rx);

/* Feed one received byte. Returns the payload size (>= 1, payload at rx->buf)
 * when b completes a valid frame, 0 otherwise. The payload stays valid until
 * the next call. */
size_t link_rx_byte(link_rx_t *rx, uint8_t b);

/* Frame and queue a payload of n <= ACNF_MAX_UP_SIZE bytes; false if it was not queued. */
bool link_send(const uint8_t *payload, size_t n);

/* Frame a payload into out (room for n + 6 bytes), delimiter included; returns the size. */
size_t link_frame(const uint8_t *payload, size_t n, uint8_t *out);

#endif
