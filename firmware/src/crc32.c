#include "crc32.h"

/* On the AVR a const table is copied into RAM at start unless it is kept in flash and read from
 * there: 64 B of an Uno's 2 KB. */
#if defined(__AVR__)
#include <avr/pgmspace.h>
#define CRC_FLASH PROGMEM
#define CRC_NIBBLE(i) pgm_read_dword(&crc_nibble[i])
#else
#define CRC_FLASH
#define CRC_NIBBLE(i) crc_nibble[i]
#endif

/* Remainder of each 4-bit value under the reflected polynomial. */
static const uint32_t crc_nibble[16] CRC_FLASH = {
    0x00000000u, 0x1db71064u, 0x3b6e20c8u, 0x26d930acu, 0x76dc4190u, 0x6b6b51f4u,
    0x4db26158u, 0x5005713cu, 0xedb88320u, 0xf00f9344u, 0xd6d6a3e8u, 0xcb61b38cu,
    0x9b64c2b0u, 0x86d3d2d4u, 0xa00ae278u, 0xbdbdf21cu,
};

uint32_t crc32_update(uint32_t crc, const uint8_t *p, size_t n)
{
    size_t i;
    crc = ~crc;
    for (i = 0; i < n; ++i) {
        crc ^= p[i];
        crc = (crc >> 4) ^ CRC_NIBBLE(crc & 0x0fu);
        crc = (crc >> 4) ^ CRC_NIBBLE(crc & 0x0fu);
    }
    return ~crc;
}
