/* Numbers of CSV lines: see csvnum.h.
 *
 * Each number is rounded correctly, as Python's float() (numpy's reader) rounds it. A mantissa of
 * at most 19 significant digits, at most 2^53, times or over a power of ten up to 1e22 is one IEEE
 * operation on two exact doubles, hence correctly rounded. Every other number goes to strtod
 * (correctly rounded in glibc and the BSDs) written as digits and an exponent only, with no decimal
 * point, so that no locale's radix character can change what it reads. */
#include "csvnum.h"
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_DIGITS 19 /* a uint64 holds any 19 decimal digits */
#define SCRATCH 400   /* longest field given to strtod; a longer one is refused (numpy takes it) */
#define EXP_CLAMP 100000L /* past +-this (< SCRATCH digits) every value is inf or 0 */

static const double pow10_exact[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                       1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                       1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

static int is_digit(uint8_t c)
{
    return c >= '0' && c <= '9';
}

static int is_blank(uint8_t c)
{
    return c == ' ' || c == '\t';
}

/* The number in p[0..n) into *v; 0 when the field is outside the grammar (csvnum.h). Any number. */
static int parse_any(const uint8_t *p, int64_t n, int comma_is_point, double *v)
{
    int64_t i = 0, sig = 0, digits = 0, nfrac = 0, k = 0, num, mend;
    int neg = 0, inexact = 0;
    uint64_t m = 0;
    long scale = 0, written = 0; /* value = m * 10^(scale + written) */
    char scratch[SCRATCH + 32];
    char *end;

    while (i < n && is_blank(p[i]))
        i++;
    while (n > i && is_blank(p[n - 1]))
        n--;
    if (n - i > SCRATCH)
        return 0;
    if (i < n && (p[i] == '+' || p[i] == '-'))
        neg = p[i++] == '-';
    for (num = i; i < n && is_digit(p[i]); i++, digits++) {
        if (m == 0 && p[i] == '0')
            continue; /* a leading zero */
        if (sig < MAX_DIGITS) {
            m = m * 10u + (uint64_t)(p[i] - '0');
            sig++;
        } else {
            inexact = 1;
            scale++; /* a dropped integer digit scales what was kept */
        }
    }
    if (i < n && (p[i] == '.' || (comma_is_point && p[i] == ','))) {
        for (i++; i < n && is_digit(p[i]); i++, digits++, nfrac++) {
            if (m == 0 && p[i] == '0') {
                scale--;
            } else if (sig < MAX_DIGITS) {
                m = m * 10u + (uint64_t)(p[i] - '0');
                sig++;
                scale--;
            } else {
                inexact = 1;
            }
        }
    }
    if (digits == 0)
        return 0;
    mend = i;
    if (i < n && (p[i] == 'e' || p[i] == 'E')) {
        long x = 0, sign = 1;
        int64_t start;
        i++;
        if (i < n && (p[i] == '+' || p[i] == '-'))
            sign = p[i++] == '-' ? -1 : 1;
        for (start = i; i < n && is_digit(p[i]); i++)
            if (x <= EXP_CLAMP)
                x = x * 10 + (p[i] - '0');
        if (i == start)
            return 0;
        written = sign * (x > EXP_CLAMP ? EXP_CLAMP : x);
    }
    if (i != n)
        return 0;
    if (m == 0) {
        *v = neg ? -0.0 : 0.0;
        return 1;
    }
    scale += written;
    if (!inexact && m <= (UINT64_C(1) << 53) && scale >= -22 && scale <= 22) {
        double d = (double)m; /* exact: m <= 2^53 */
        d = scale >= 0 ? d * pow10_exact[scale] : d / pow10_exact[-scale];
        *v = neg ? -d : d;
        return 1;
    }
    /* every digit as written, the fraction's count taken off the exponent: "12.5e3" -> "125e2" */
    if (neg)
        scratch[k++] = '-';
    for (; num < mend; num++)
        if (is_digit(p[num]))
            scratch[k++] = (char)p[num];
    k += snprintf(scratch + k, sizeof scratch - (size_t)k, "e%ld", written - (long)nfrac);
    *v = strtod(scratch, &end);
    return end == scratch + k;
}

/* parse_any's result for a field, faster for the common one: no exponent, at most 19 significant
 * digits, a value below 2^53 with at most 22 decimals (m / 10^nfrac: one correctly rounded
 * division) */
static int parse_number(const uint8_t *p, int64_t n, int comma_is_point, double *v)
{
    int64_t i = 0, s, digits, nfrac = 0, sig;
    uint64_t m = 0;
    int neg = 0;
    double d;

    while (i < n && is_blank(p[i]))
        i++;
    while (n > i && is_blank(p[n - 1]))
        n--;
    if (i < n && (p[i] == '+' || p[i] == '-'))
        neg = p[i++] == '-';
    s = i;
    while (i < n && p[i] == '0')
        i++; /* leading zeros */
    for (sig = i; i < n && is_digit(p[i]); i++)
        m = m * 10u + (uint64_t)(p[i] - '0'); /* wraps past 19 digits: then refused below */
    sig = i - sig;
    digits = i - s;
    if (i < n && (p[i] == '.' || (comma_is_point && p[i] == ','))) {
        int64_t f = ++i;
        if (m == 0)
            while (i < n && p[i] == '0')
                i++; /* zeros before the first significant digit */
        for (s = i; i < n && is_digit(p[i]); i++)
            m = m * 10u + (uint64_t)(p[i] - '0');
        sig += i - s;
        nfrac = i - f;
        digits += nfrac;
    }
    if (i != n || digits == 0 || sig > MAX_DIGITS || m > (UINT64_C(1) << 53) || nfrac > 22)
        return parse_any(p, n, comma_is_point, v); /* an exponent, many digits, or not a number */
    d = (double)m;                                 /* exact: m <= 2^53 */
    if (nfrac)
        d /= pow10_exact[nfrac];
    *v = neg ? -d : d;
    return 1;
}

int acsv_parse(const uint8_t *buf, int64_t len, int delim, int comma_is_point, int64_t ncols,
               const int64_t *slot, int64_t nuse, int64_t nrows, double *out, int64_t *bad)
{
    int64_t pos = 0, row = 0, j;
    bad[0] = bad[1] = -1;
    if (len < 0 || ncols < 1 || nuse < 0 || nrows < 0 || delim < 0 || delim > 255 ||
        delim == '\n' || (nuse > 0 && nrows > INT64_MAX / nuse))
        return ACSV_ARGS;
    for (j = 0; j < ncols; j++)
        if (slot[j] < -1 || slot[j] >= nuse)
            return ACSV_ARGS;
    for (;;) {
        if (row >= nrows) {
            bad[0] = row;
            return ACSV_ROWS;
        }
        if (pos >= len || buf[pos] == '\n') {
            bad[0] = row;
            return ACSV_FIELDS; /* an empty line (the numpy reader skips it) */
        }
        for (j = 0; j < ncols; j++) {
            int64_t start = pos;
            while (pos < len && buf[pos] != delim && buf[pos] != '\n')
                pos++;
            if (slot[j] >= 0 && !parse_number(buf + start, pos - start, comma_is_point,
                                              out + row * nuse + slot[j])) {
                bad[0] = row;
                bad[1] = j;
                return ACSV_FIELD;
            }
            if (j + 1 < ncols) {
                if (pos >= len || buf[pos] != delim) {
                    bad[0] = row;
                    return ACSV_FIELDS; /* too few fields */
                }
                pos++;
            }
        }
        if (pos < len && buf[pos] != '\n') {
            bad[0] = row;
            return ACSV_FIELDS; /* too many fields */
        }
        row++;
        if (pos >= len)
            break;
        pos++; /* the '\n' */
    }
    if (row != nrows) {
        bad[0] = row;
        return ACSV_ROWS;
    }
    return ACSV_OK;
}

/*
 * np.rint(q).astype(np.int64): round half to even, then numpy's cast on x86-64 (cvttsd2si), which
 * gives INT64_MIN out of range or for NaN. Below 2^51 in magnitude the rounding is q + 1.5 2^52
 * - 1.5 2^52 (the sum's unit in the last place is 1; the same result as rint, without its call:
 * half the pass).
 */
static int64_t grid_index(double q)
{
    const double magic = 6755399441055744.0; /* 1.5 * 2^52 */
    double r;
    if (fabs(q) < 2251799813685248.0) /* 2^51 */
        r = (q + magic) - magic;
    else
        r = rint(q);
    if (!(r >= -9223372036854775808.0 && r < 9223372036854775808.0))
        return INT64_MIN;
    return (int64_t)r;
}

int acsv_grid_block(int64_t m, int64_t naxes, const double *t, const double *accel, double t0,
                    double Ts, int64_t k_prev, int first, int64_t nalt, const double *ratio,
                    double thr, int64_t *found, int64_t *beyond)
{
    /* the findings and counts in locals (the counts of ACSV_GRID_CELLS axis-units at most, the rest
     * in place): stores through found and beyond could alias the rows, which kept every test in
     * memory */
    enum { ACSV_GRID_CELLS = 32 };
    const double quarter = 0.25 * Ts;
    int64_t i, j, a, prev = k_prev, nonfinite = -1, off = -1, dup = -1, gap = 0;
    int64_t cells = naxes * nalt, local[ACSV_GRID_CELLS] = {0};
    int64_t *count = cells <= ACSV_GRID_CELLS ? local : beyond;
    if (m < 1 || naxes < 1 || nalt < 0 || naxes > INT64_MAX / (nalt > 0 ? nalt : 1))
        return ACSV_ARGS;
    for (i = 0; i < cells; i++)
        count[i] = 0;
    for (i = 0; i < m; i++) {
        const double *row = accel + i * naxes;
        /* k = rint((t - t0) / Ts); off = |t - t0 - k Ts| > Ts / 4, in the twin's order */
        int64_t k = grid_index((t[i] - t0) / Ts);
        if (off < 0 && fabs(t[i] - t0 - (double)k * Ts) > quarter)
            off = i;
        if (i > 0 || !first) { /* dk = k - previous k (two's complement, as numpy's int64) */
            int64_t dk = (int64_t)((uint64_t)k - (uint64_t)prev);
            if (dup < 0 && dk < 1)
                dup = first ? i - 1 : i;
            gap |= dk > 1;
        }
        prev = k;
        for (j = 0; j < naxes; j++) {
            double v = row[j];
            if (!isfinite(v)) {
                if (nonfinite < 0)
                    nonfinite = i;
                continue;
            }
            for (a = 0; a < nalt; a++)
                count[j * nalt + a] += fabs(v) * ratio[j * nalt + a] > thr;
        }
    }
    if (count == local)
        for (i = 0; i < cells; i++)
            beyond[i] = local[i];
    found[0] = nonfinite, found[1] = off, found[2] = dup, found[3] = gap, found[4] = prev;
    return ACSV_OK;
}

/* the slot of key in a table of size (a power of two) keys, or the empty one it would take */
static int64_t step_slot(const uint64_t *keys, const int64_t *index, int64_t size, uint64_t key)
{
    uint64_t h =
        key * 0x9E3779B97F4A7C15ULL; /* Fibonacci hashing: the high bits spread the steps */
    int64_t i = (int64_t)(h >> 32) & (size - 1);
    while (index[i] >= 0 && keys[i] != key)
        i = (i + 1) & (size - 1);
    return i;
}

int acsv_time_block(int64_t m, const double *t, int has_prev, double prev, int64_t cap,
                    int64_t *found, double *range, double *vals, int64_t *counts)
{
    int64_t i, size = 2, distinct = 0, nonfinite = -1, back = -1, n_back = 0;
    double dmin = INFINITY, dmax = -INFINITY;
    uint64_t *keys;
    int64_t *index; /* per slot: the step's place in vals and counts, -1 for an empty slot */
    if (m < 1 || cap < 1 || cap > (INT64_MAX >> 3))
        return ACSV_ARGS;
    for (i = 0; i < m; i++)
        if (!isfinite(t[i])) {
            nonfinite = i;
            break;
        }
    while (size < 2 * cap)
        size <<= 1;
    keys = malloc((size_t)size * sizeof *keys);
    index = malloc((size_t)size * sizeof *index);
    if (keys == NULL || index == NULL) {
        free(keys);
        free(index);
        return ACSV_ARGS;
    }
    for (i = 0; i < size; i++)
        index[i] = -1;
    for (i = has_prev ? 0 : 1; i < m; i++) {
        double d = t[i] - (i == 0 ? prev : t[i - 1]); /* np.diff's t[i] - t[i - 1] */
        if (d <= 0.0) {
            if (back < 0)
                back = has_prev ? i : i - 1;
            n_back++;
        }
        if (nonfinite >= 0 || distinct < 0)
            continue; /* the steps are not counted then */
        dmin = d < dmin ? d : dmin, dmax = d > dmax ? d : dmax;
        {
            double key_d = d == 0.0 ? 0.0 : d; /* -0.0 == 0.0, as np.unique has them */
            uint64_t key;
            int64_t slot;
            memcpy(&key, &key_d, sizeof key);
            slot = step_slot(keys, index, size, key);
            if (index[slot] >= 0) {
                counts[index[slot]]++;
            } else if (distinct == cap) {
                distinct = -1; /* more distinct steps than cap: the caller counts them */
            } else {
                keys[slot] = key, index[slot] = distinct;
                vals[distinct] = key_d, counts[distinct] = 1;
                distinct++;
            }
        }
    }
    free(keys);
    free(index);
    found[0] = nonfinite, found[1] = back, found[2] = n_back;
    found[3] = nonfinite >= 0 ? -1 : distinct;
    range[0] = dmin, range[1] = dmax;
    return ACSV_OK;
}
