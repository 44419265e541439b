/*
 * The C twin of codegen/gains.py's float64 Riccati recursion, schedule search and
 * error account, and of codegen/bounds.py's bound recursion: the same operations
 * in the same order on IEEE doubles, so that it gives the very same numbers as the
 * Python. It must be compiled without contraction or fast math (-ffp-contract=off
 * -fno-fast-math, ISO C99): codegen/riccati_build.py (the wheel) and gains.py's
 * run-time build (the cffi builder) both do.
 *
 * The declarations between the ACN-CDEF markers are what cffi exposes.
 */
#ifndef ACCELNAV_RICCATI_H
#define ACCELNAV_RICCATI_H

/* ACN-CDEF-BEGIN */
void acn_riccati(long n, const double *par, const double *P0, const unsigned char *valid, long keep,
                 long nrows, const long *rows, double *K, double *sig, double *S_all,
                 double *mprior, double *mpost, double *mc, double *rowP, double *rowK,
                 double *rowsig, double *rowS, double *ext);
void acn_bound(long n, const double *par, const double *P0, const double *bp, long nrows,
               const long *rows, double *out);
void acn_bound_loop(long m, long k0, const double *bp, const double *K, const double *dK,
                    const double *y, const double *a, const double *dw, const unsigned char *valid,
                    double *st, double *out);
long acn_cone(long m, long L0, const double *K, const double *par, const double *A,
              const unsigned char *hold, double *lohi);
int acn_account(long m, const long long *A, const long long *sl, const long long *ex,
                const double *lsb, const double *K, double *maxerr, long nhead, double *head);
/* ACN-CDEF-END */

#endif
