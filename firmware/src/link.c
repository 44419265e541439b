#include "link.h"

#include <string.h>

#include "acn_board.h"
#include "cobs.h"
#include "crc32.h"

void link_rx_init(link_rx_t *rx)
{
    rx->len = 0;
    rx->overlong = false;
    rx->errors = 0;
}

size_t link_rx_byte(link_rx_t *rx, uint8_t b)
{
    size_t n;
    uint32_t crc;
    if (b != 0u) {
        if (rx->len < LINK_RX_MAX) {
            rx->buf[rx->len++] = b;
        } else {
            rx->overlong = true;
        }
        return 0;
    }
    /* a delimiter ends the frame */
    n = rx->len;
    rx->len = 0;
    if (rx->overlong) {
        rx->overlong = false;
        ++rx->errors;
        return 0;
    }
    if (n == 0u) { /* back-to-back delimiters: idle line, not an error */
        return 0;
    }
    n = cobs_decode(rx->buf, n, rx->buf);
    if (n == COBS_ERROR || n < 5u) { /* type byte + CRC at least */
        ++rx->errors;
        return 0;
    }
    n -= 4u;
    crc = (uint32_t)rx->buf[n] | (uint32_t)rx->buf[n + 1u] << 8 | (uint32_t)rx->buf[n + 2u] << 16 |
          (uint32_t)rx->buf[n + 3u] << 24;
    if (crc != crc32_update(0u, rx->buf, n)) {
        ++rx->errors;
        return 0;
    }
    return n;
}

size_t link_frame(const uint8_t *payload, size_t n, uint8_t *out)
{
    uint8_t *raw = out + 1; /* payload || CRC, encoded in place: no third copy on the stack (2 KiB
                               of RAM on an ATmega328P) */
    uint32_t crc;
    size_t w;
    if (n > ACNF_MAX_UP_SIZE) {
        return 0;
    }
    crc = crc32_update(0u, payload, n);
    memmove(raw, payload, n);
    raw[n] = (uint8_t)crc;
    raw[n + 1u] = (uint8_t)(crc >> 8);
    raw[n + 2u] = (uint8_t)(crc >> 16);
    raw[n + 3u] = (uint8_t)(crc >> 24);
    /* in place: encoding byte i writes out[i + 1] (a frame is shorter than one 254-byte COBS group)
     * or an earlier code byte, never a byte not yet read */
    w = cobs_encode(raw, n + 4u, out);
    out[w++] = 0u;
    return w;
}

bool link_send(const uint8_t *payload, size_t n)
{
    uint8_t wire[ACNF_MAX_UP_WIRE];
    size_t w = link_frame(payload, n, wire);
    return w > 0u && board_uart_write(wire, w);
}
