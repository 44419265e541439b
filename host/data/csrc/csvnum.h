/*
 * The numbers of a CSV body's whole lines in one call: the C reader of host/data/csvnum.py. It
 * accepts a strict subset of what the numpy reader (np.loadtxt) accepts and gives the very same
 * doubles; anything else it reports (its row and field) and the numpy reader takes the piece.
 * The declarations between the ACN-CDEF markers are what cffi exposes.
 */
#ifndef ACCELNAV_CSVNUM_H
#define ACCELNAV_CSVNUM_H

#include <stdint.h>

/* acsv_parse's results: 0 every line parsed; else the first thing outside its grammar */
#define ACSV_OK 0
#define ACSV_FIELD 1  /* a wanted field is not a plain decimal number (bad[1]: its column) */
#define ACSV_FIELDS 2 /* a line with another number of fields, or an empty line */
#define ACSV_ROWS 3   /* the buffer holds another number of lines than nrows */
#define ACSV_ARGS 4   /* the arguments disagree (a length, a count or a slot out of range) */

/* ACN-CDEF-BEGIN */
int acsv_parse(const uint8_t *buf, int64_t len, int delim, int comma_is_point, int64_t ncols,
               const int64_t *slot, int64_t nuse, int64_t nrows, double *out, int64_t *bad);
int acsv_grid_block(int64_t m, int64_t naxes, const double *t, const double *accel, double t0,
                    double Ts, int64_t k_prev, int first, int64_t nalt, const double *ratio,
                    double thr, int64_t *found, int64_t *beyond);
int acsv_time_block(int64_t m, const double *t, int has_prev, double prev, int64_t cap,
                    int64_t *found, double *range, double *vals, int64_t *counts);
/* ACN-CDEF-END */

/*
 * buf[0..len): lines ended by '\n' (the last one need not be); each line has ncols fields split by
 * the byte delim. slot[j] (j < ncols) is the output column of field j, or -1 for a field not
 * wanted (skipped unread); every output column 0..nuse-1 is some field's. out holds nrows * nuse
 * doubles, row by row. bad[0] and bad[1] get the row and the field of what was refused (-1 where
 * none applies). A wanted field is: optional spaces or tabs, an optional sign, digits with an
 * optional decimal point ('.', or ',' too when comma_is_point) and at least one digit, an optional
 * exponent (e or E, optional sign, digits), optional spaces or tabs. Never read beyond buf[len -
 * 1], never written beyond out[nrows * nuse - 1].
 */

/*
 * acsv_grid_block: the grid pass of a streamed recording (host/data/stream.py, _grid_pass) over one
 * block of m rows in one pass, the numbers its numpy twin (stream._grid_numpy) computes: t (m) in
 * s, accel (m x naxes, by rows) in m/s^2, t0 and Ts the grid, k_prev the grid index of the row
 * before the block (unused when first). found[0]: the first row with a non-finite accel (-1: none);
 * found[1]: the first row off the grid by more than Ts / 4; found[2]: the first index of a grid
 * step below 1, as the twin's np.diff indexes it (-1: none); found[3]: 1 if a grid step exceeds 1;
 * found[4]: the grid index of the last row. beyond[j * nalt + a]: the finite samples of axis j
 * with |accel| * ratio[j * nalt + a] > thr. Returns 0, or ACSV_ARGS (m < 1, naxes < 1, nalt < 0).
 *
 * acsv_time_block: the time pass (stream._time_pass) over one block of m stamps t, after prev (when
 * has_prev), the steps dt as its numpy twin takes them (np.diff, prev first). found[0]: the first
 * non-finite stamp (-1: none); found[1]: the first step <= 0, by np.diff's index (-1: none);
 * found[2]: how many steps are <= 0; found[3]: the number of distinct steps in vals (their counts
 * in counts, in no order; -0.0 counted as 0.0), or -1 when there are more than cap (or a stamp is
 * not finite: no steps counted then); range: the least and the largest step. Returns 0, or
 * ACSV_ARGS.
 */

#endif
