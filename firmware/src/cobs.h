/* Consistent Overhead Byte Stuffing: a payload without any 0x00 byte, so that
 * 0x00 can end a frame. Each group starts with a code byte c (1..255): c - 1
 * data bytes follow, then an implied 0x00 unless c is 255 or the group is the
 * last. An n-byte payload (n < 254) always encodes to n + 1 bytes. */
#ifndef ACN_COBS_H
#define ACN_COBS_H

#include <stddef.h>
#include <stdint.h>

#define COBS_ERROR ((size_t)-1)
/* Worst-case encoded size of n bytes. */
#define COBS_MAX_ENCODED(n) ((n) + (n) / 254u + 1u)

/* Encode n bytes of in to out (room for COBS_MAX_ENCODED(n)); returns the size written.
 * No delimiter is written. in and out must not overlap. */
size_t cobs_encode(const uint8_t *in, size_t n, uint8_t *out);

/* Decode n bytes (no delimiter) into out, which may equal in (the output never
 * runs ahead of the input). Returns the decoded size, or COBS_ERROR when a code
 * byte is 0 or points past the end. */
size_t cobs_decode(const uint8_t *in, size_t n, uint8_t *out);

#endif
