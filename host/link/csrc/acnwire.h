/*
 * COBS decoding and CRC-32 checking of many equal-length frames in one call: the
 * C kernel of host/link/wirekernel.py (the decoder's numpy path does the same).
 * The declarations between the ACN-CDEF markers are what cffi exposes.
 */
#ifndef ACCELNAV_ACNWIRE_H
#define ACCELNAV_ACNWIRE_H

#include <stdint.h>

/* ACN-CDEF-BEGIN */
void acnw_decode(const uint8_t *buf, const int64_t *start, int64_t n, int64_t L, uint8_t *dec,
                 uint8_t *ok, uint8_t *crc);
/* ACN-CDEF-END */

#endif
