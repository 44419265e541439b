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

#endif
