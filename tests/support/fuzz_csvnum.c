/*
 * libFuzzer harness of the CSV reader's C parser (host/data/csrc/csvnum.c), built with ASan and
 * UBSan by tests/data/test_csvnum_fuzz.py. The input's first three bytes choose the delimiter, the
 * number of fields and which are wanted; the rest is the piece, copied into a buffer of exactly its
 * length (and the output sized exactly), so a read or write past either is a crash. Every number
 * the parser accepts is checked against strtod on that field alone (NUL-terminated, the decimal
 * comma made a point, the C locale): the exact fast path must give strtod's correctly rounded bits.
 */
#include "csvnum.h"
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static int field_bounds(const uint8_t *buf, size_t len, uint8_t delim, int64_t row, int64_t col,
                        size_t *a, size_t *b)
{
    size_t pos = 0;
    int64_t r = 0, c = 0;
    while (r < row || c < col) {
        if (pos >= len)
            return 0;
        if (buf[pos] == '\n') {
            r++;
            c = 0;
        } else if (buf[pos] == delim && r == row) {
            c++;
        }
        pos++;
    }
    *a = pos;
    while (pos < len && buf[pos] != delim && buf[pos] != '\n')
        pos++;
    *b = pos;
    return 1;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const uint8_t delims[3] = {',', ';', '\t'};
    int64_t ncols, nuse = 0, nrows = 1, slot[8], col_of[8], j, r, bad[2];
    uint8_t delim, *buf;
    size_t len, i;
    double *out;
    int rc;

    if (size < 3)
        return 0;
    delim = delims[data[0] % 3];
    ncols = 1 + data[1] % 8;
    for (j = 0; j < ncols; j++) {
        slot[j] = ((data[2] >> j) & 1) ? nuse : -1;
        if (slot[j] >= 0)
            col_of[nuse++] = j;
    }
    if (nuse == 0)
        return 0;
    len = size - 3;
    buf = malloc(len ? len : 1);
    memcpy(buf, data + 3, len);
    for (i = 0; i < len; i++)
        nrows += buf[i] == '\n';
    out = malloc(sizeof(double) * (size_t)(nrows * nuse));
    rc = acsv_parse(buf, (int64_t)len, delim, delim != ',', ncols, slot, nuse, nrows, out, bad);
    if (rc == ACSV_OK) {
        for (r = 0; r < nrows; r++)
            for (j = 0; j < nuse; j++) {
                size_t a, b;
                char text[512], *end;
                double want;
                if (!field_bounds(buf, len, delim, r, col_of[j], &a, &b) || b - a >= sizeof text)
                    abort(); /* an accepted field the harness cannot find, or longer than accepted
                              */
                for (i = a; i < b; i++)
                    text[i - a] = (delim != ',' && buf[i] == ',') ? '.' : (char)buf[i];
                text[b - a] = '\0';
                want = strtod(text, &end);
                if (memcmp(&want, &out[r * nuse + j], sizeof want) != 0)
                    abort(); /* not strtod's bits */
            }
    } else if (rc != ACSV_FIELD && rc != ACSV_FIELDS && rc != ACSV_ROWS) {
        abort(); /* the arguments were consistent */
    } else if (bad[0] < 0 || bad[0] > nrows || bad[1] < -1 || bad[1] >= ncols) {
        abort(); /* a refusal must say where */
    }
    free(out);
    free(buf);
    return 0;
}
