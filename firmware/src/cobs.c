#include "cobs.h"

size_t cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t i;
    size_t code_at = 0; /* where the current group's code byte goes */
    size_t w = 1;
    uint8_t code = 1; /* 1 + data bytes in the current group */
    for (i = 0; i < n; ++i) {
        if (in[i] == 0u) {
            out[code_at] = code;
            code_at = w++;
            code = 1;
            continue;
        }
        out[w++] = in[i];
        if (++code == 0xffu) { /* a full group: no implied zero */
            out[code_at] = code;
            code_at = w++;
            code = 1;
        }
    }
    out[code_at] = code;
    return w;
}

size_t cobs_decode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t r = 0;
    size_t w = 0;
    while (r < n) {
        uint8_t code = in[r++];
        size_t run;
        if (code == 0u) {
            return COBS_ERROR;
        }
        run = (size_t)code - 1u;
        if (run > n - r) {
            return COBS_ERROR;
        }
        while (run-- > 0u) {
            out[w++] = in[r++]; /* w < r: safe in place */
        }
        if (code != 0xffu && r < n) {
            out[w++] = 0u;
        }
    }
    return w;
}
