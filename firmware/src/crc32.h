/* CRC-32 (IEEE 802.3, the zlib one): reflected polynomial 0xEDB88320, initial
 * value and final xor 0xFFFFFFFF. A 16-entry table (64 bytes of flash), two
 * lookups per byte. */
#ifndef ACN_CRC32_H
#define ACN_CRC32_H

#include <stddef.h>
#include <stdint.h>

/* CRC of n bytes at p; chain calls with crc32_update(crc32_update(0, a, na), b, nb). */
uint32_t crc32_update(uint32_t crc, const uint8_t *p, size_t n);

#endif
