/*
 * Float64 Kalman filter and Rauch-Tung-Striebel smoother of one accelnav axis,
 * state x = [r, u, a, eps] (position, velocity, acceleration, bias).
 *
 * Conventions are those of host/kf.py (the reference): F maps x[k] to x[k+1],
 * x[k+1] = F x[k] + b + w, w ~ N(0, Q); the prior of sample 0 is (x0, P0); at
 * sample k the filter predicts (k >= 1), applies z[k] = a + eps + v unless the
 * sample is invalid, then the extra scalar measurements of sample k in order.
 *
 * Symmetric 4x4 matrices are stored packed, 10 doubles, upper triangle by rows:
 *   rr ru ra re  uu ua ue  aa ae  ee
 *
 * Two paths:
 *   plain:   no extra measurements. The covariances and gains do not depend on
 *            the data (only on the model and the valid mask), so they are
 *            computed once (acn_plain_cov) and reused by a cheap data pass
 *            (acn_plain_data). See host/fastsmooth.py for the proof that the
 *            reduced smoother is the 4-state RTS smoother.
 *   general: any scalar extras (position fixes, zero-velocity updates), full
 *            4-state filter and RTS smoother (acn_general).
 */
#ifndef ACCELNAV_FASTSMOOTH_H
#define ACCELNAV_FASTSMOOTH_H

#define ACN_FASTSMOOTH_API 1
/* the figures of one verdict of the rest decision's forward filter (acn_kin_fwd_out.num) */
#define ACN_KIN_NUM 8

/* ACN-CDEF-BEGIN */
typedef struct {
    double f01, f02, f12; /* F[0][1] = Ts, F[0][2] = Ts^2/2, F[1][2] = Ts */
    double phi, b_eps;    /* eps[k+1] = phi eps[k] + b_eps */
    double q[10];         /* Q, packed */
    double R;             /* variance of the acceleration measurement */
    double x0[4];         /* prior mean of sample 0 */
    double p0[10];        /* prior covariance of sample 0, packed */
    double gr, gu;        /* Q_ra / Q_aa, Q_ua / Q_aa: E[w_r | w_a] = gr w_a */
} acn_axis;

int acn_plain_cov(const acn_axis *m, long n, const unsigned char *valid, double *K, double *Cs,
                  double *Pprior, double *Ppost, double *Psm);

int acn_plain_rows(const acn_axis *m, long n, double *rows);

int acn_plain_cov_steady(const acn_axis *m, long n, long nt, const double *rows, double *Pprior,
                         double *Ppost, double *Psm);

/* K, Cs: rows stride doubles apart; sample k >= nk uses row nk - 1 (a stored steady row) */
void acn_plain_data(const acn_axis *m, long n, const double *z, const unsigned char *valid,
                    const double *K, const double *Cs, long stride, long nk, double *xf,
                    double *xs);

int acn_general(const acn_axis *m, long n, const double *z, const unsigned char *valid,
                long n_extra, const long *ek, const double *eh, const double *ez, const double *eR,
                const double *egate, unsigned char *applied, double *ey, double *eS, double *xprior,
                double *Pprior, double *xpost, double *Ppost, double *xs, double *Psm);

/*
 * The rest detector's split of one run of n quiet window centres into pieces of
 * steady level (host/estimate/zupt.py, _steady_pieces). means, x: n rows of
 * n_axes (at most ACN_REST_MAX_AXES) window means and samples of the run.
 * tilt_rate, leak_rate: level drift allowed per row (beyond lean rows; over a
 * whole run). scratch: n doubles the kernel overwrites (the caller's, so a long
 * rest's run does not cost another 8 B a row). Writes each piece's first and
 * last + 1 row, its median level (n_axes) and its own variance (summed over
 * axes) into arrays of n; returns the number of pieces, -1 when out of memory,
 * -2 for too many axes.
 */
enum { ACN_REST_MAX_AXES = 7 }; /* zupt._MAX_AXES: numpy sums up to 7 terms in order */

long acn_rest_pieces(long n, int n_axes, const double *means, const double *x, double bound2,
                     double total, long w, double tilt_rate, long lean, double leak_rate,
                     double *scratch, long *pstart, long *pstop, double *pref, double *pown);
/*
 * The median of v[0..n-1] as np.median gives it: NaN where any value is NaN or
 * n < 1, the mean of the two middle values for an even n. v is reordered.
 */
double acn_rest_median(long n, double *v);
/*
 * The widening of count pieces (host/estimate/zupt.py, _level_steps): for piece
 * i, how many rows past edge[i] (walking by step, -1 or 1; at most h) stay inside
 * the n rows of x (n_axes columns), usable, and within lim2[i] (squared, summed
 * over the axes in order) of its level refs[i] (n_axes), before the first that
 * does not. Into out (count). Returns 0, or -1 (nothing written) where a length
 * or step is out of range.
 */
long acn_rest_widen(long n, int n_axes, const double *x, const unsigned char *usable, long count,
                    const double *refs, const double *lim2, const long *edge, int step, long h,
                    long *out);

/*
 * Plain path in bounded memory (host/estimate/chunked.py): the same numbers as
 * acn_plain_cov + acn_plain_data, computed chunk by chunk in three passes over
 * a store of ACN_ROW doubles per sample (kept on disk by the caller):
 *   acn_chunk_fwd  forward, filter means and covariances, smoother gains;
 *   acn_chunk_bwd  backward, (a, eps) smoothed means and covariances;
 *   acn_chunk_ru   forward, smoothed r, u and their covariances.
 * The general path likewise in two passes over ACN_GROW doubles per sample
 * (acn_chunkg_fwd, acn_chunkg_bwd): the same steps as acn_general.
 * The carried state between chunks is a small array documented at each call.
 */
enum { ACN_ROW = 12, ACN_GROW = 14, ACN_SROW = 14, ACN_LROW = 2, ACN_GLROW = 4 };

int acn_chunk_fwd(const acn_axis *m, long k0, long n, int last, const double *z,
                  const unsigned char *valid, double *carry, double *store, double *xf, double *sdf,
                  double *Pf0, double *Pfn);

/* sdf NULL: the filter's states unwanted, the steady covariance jumped over (fastsmooth.c);
 * x32 != NULL: r, u and their sds as float (2 a sample each, x32, sd32), xf and sdf two rows: the
 * chunk's first and last sample's */
int acn_chunk_fwd_steady(const acn_axis *m, long k0, long n, int last, const double *z,
                         const double *srows, long nt, double *carry, double *store, double *xf,
                         double *sdf, double *Pf0, double *Pfn, float *x32, float *sd32);
void acn_chunk_bwd(const acn_axis *m, long n, int last, double *store, double *carry);

/* all-valid samples from the steady rows: a lean store of ACN_LROW doubles per sample (a, eps);
 * their smoothed covariance is data-independent: acn_chunk_cov_lean computes it again per chunk */
void acn_chunk_bwd_lean(const acn_axis *m, long k0, long n, int last, const double *srows, long nt,
                        double *store, double *carry);

void acn_chunk_cov_lean(const acn_axis *m, long k0, long n, int last, const double *srows, long nt,
                        const double *after, double *cov);

/* x32 != NULL: r, u and their sds only, as float (2 a sample each, x32, sd32); xs, sds unused */
void acn_chunk_ru_lean(const acn_axis *m, long k0, long n, const double *store, const double *cov,
                       const double *srows, long nt, double *carry, double *xs, double *sds,
                       float *x32, float *sd32);

void acn_chunkg_fwd(const acn_axis *m, long n, int last, const double *z,
                    const unsigned char *valid, long n_extra, const long *ek, const double *eh,
                    const double *ez, const double *eR, const double *egate, unsigned char *applied,
                    double *carry, double *store, double *xf, double *sdf, double *xpr, double *ppr,
                    double *ey, double *eS);

int acn_chunkg_bwd(const acn_axis *m, long k0, long n, int last, const double *store, double *carry,
                   double *xs, double *sds, double *ps);

/* the general path with a lean store of ACN_GLROW doubles per sample (the posterior mean): its
 * covariance made again per chunk by acn_chunkg_cov for the backward pass (fastsmooth.c) */
void acn_chunkg_fwd_lean(const acn_axis *m, long n, int last, const double *z,
                         const unsigned char *valid, long n_extra, const long *ek, const double *eh,
                         const double *ez, const double *eR, const double *egate,
                         unsigned char *applied, double *carry, double *store, double *xf,
                         double *sdf, double *ey, double *eS);

void acn_chunkg_cov(const acn_axis *m, long n, int last, const unsigned char *valid, long n_extra,
                    const long *ek, const double *eh, const double *eR,
                    const unsigned char *applied, const double *p0, double *pst);

/* a digest of n aids as acn_chunkg_cov reads them (samples, h, R): the backward pass checks that
 * the aids it was given again are the forward pass's own (fastsmooth.c) */
unsigned long long acn_aids_digest(long n, const long *ek, const double *eh, const double *eR);

int acn_chunkg_bwd_lean(const acn_axis *m, long k0, long n, int last, const double *xst,
                        const double *pst, double *carry, double *xs, double *sds);

void acn_chunk_ru(const acn_axis *m, long n, const double *store, double *carry, double *xs,
                  double *sds);
/*
 * The record's sums the kinematic filter reads (rests.py, _Kinematic), V, A, W
 * as acn_kin_sums gives them, without their n + 1 rows in memory: x (n rows of
 * n_axes, reverse: read last first) and checkpoints cp, the row [V, A, W] (3
 * n_axes doubles) at every `every`-th sample (n / every + 1 of them, made by
 * acn_kin_checkpoints); a sample's row is summed on from the nearest checkpoint
 * or kept row before it (at[], row: 4 rows kept, the least recently read
 * replaced), step by step as acn_kin_sums sums: the same doubles.
 * acn_kin_sums_at copies sample k's row into out. n_axes at most 8: acn_kin_checkpoints
 * returns -1 for a record its rows cannot hold, else 0; the kernels that read a
 * record (acn_kin_sums_at, acn_kin_backward, acn_kin_forward) refuse one whose
 * n, every or n_axes changed after its checkpoints were made.
 */
typedef struct {
    long n;
    int n_axes;
    const double *x;
    int reverse;
    double Ts;
    long every;
    const double *cp;
    long at[4];
    long used[4];
    long clock;
    double row[96];
    long cp_n, cp_every; /* the n and every the checkpoints were made for (acn_kin_checkpoints) */
    int cp_axes;
} acn_kin_rec;
int acn_kin_checkpoints(acn_kin_rec *r, double *cp);
int acn_kin_sums_at(acn_kin_rec *r, long k, double *out);
/*
 * The one-degree chi-square value with the upper tail of x under dof degrees of
 * freedom (rests.py, chi2_equivalent): the tail in closed form, its inverse by
 * Halley's steps on erfc; x itself for dof 1 or x not finite, inf where the
 * tail underflows.
 */
double acn_chi2_equivalent(double x, int dof);
/*
 * The rest decision's candidates (rests.py, decide): for each span [start, stop)
 * of x (n rows of n_axes), over its rows with usable[row] set, the mean per axis
 * into level (n_spans rows of n_axes) and the mean over axes of the variance / R
 * into still; a span with none usable: level 0, with one: still 1 (its variance
 * taken as R). Sums in row order, as numpy's over axis 0.
 */
void acn_kin_cands(int n_axes, const double *x, const unsigned char *usable, long n_spans,
                   const long *start, const long *stop, const double *R, double *level,
                   double *still);
/*
 * The backward filter of the rest decision (rests.py, _Decider.backward): from
 * the state s at sample 0 of the reversed record, its n_ev events in order,
 * each at sample ev_k with kind ev_kind (0: a candidate's test, 1: a fix of
 * value ev_z, variance ev_var on axis ev_i, 2: a candidate's end; ev_i the
 * candidate otherwise). A candidate with acc set is a rest: u = 0 (variance
 * sigma^2) at its test and its end. Per candidate i tested: its side (as
 * kin_side, sign -1) into out + 4 n_axes i and, as kin_test's res, its
 * chi-square read on one axis, |v| and the rms of the sds into stat + 3 i; the
 * event of the last aid before it (a fix, or the end of a rest) into aid[i]
 * (-1: none) and whether a fix came before it into fix[i].
 */
int acn_kin_backward(int n_axes, double *s, acn_kin_rec *r, double Ts, double q, const double *qv,
                     const double *R, long m, long n_ev, const long *ev_k, const int *ev_kind,
                     const long *ev_i, const double *ev_z, const double *ev_var,
                     const unsigned char *acc, const double *level, const long *len, double leak,
                     double drift, double scale, double sigma, double *out, double *stat, long *aid,
                     unsigned char *fix);
/*
 * The sums the kinematic filter reads (rests.py, _Kinematic), n + 1 rows of
 * n_axes each, over x (n rows of n_axes; reverse: its rows last first):
 * V[k] = Ts sum_{i<k} x[i], A[k] = Ts sum_{i<k} |x[i]|, W[k] = Ts sum_{i<k} V[i],
 * summed in row order as numpy's cumsum.
 */
void acn_kin_sums(long n, int n_axes, const double *x, int reverse, double Ts, double *V, double *A,
                  double *W);
/*
 * The forward filter of the rest decision (rests.py, _Decider.forward), deciding
 * online: its events as acn_kin_backward's (in order of sample), its candidates
 * [start, stop) in time order with their level (m rows of n_axes) and
 * stillness, the decision's figures (zupt.py's ZuptParams and rests.py's
 * constants), veto[i] set where a candidate was withdrawn. Marks: a pass starts
 * at candidate `resume`'s mark (a multiple of mark_every whose mark a pass left;
 * -1: at the record's start), the verdicts before it kept from the last pass.
 * Refused (-1) unless each candidate is tested once, in order, at its start and
 * ended at stop - 1 after its test, and the mark resumed from names that
 * candidate's test and samples within the record.
 */
typedef struct {
    int n_axes;
    long n; /* samples: the sums have n + 1 rows */
    acn_kin_rec *rec;
    const double *R, *qv;
    double Ts, q;
    const double *diffuse; /* the prior variances of r, u, e */
    long n_ev;
    const long *ev_k;
    const int *ev_kind;
    const long *ev_i;
    const double *ev_z, *ev_var;
    long m;
    const long *start, *stop;
    const double *level, *still;
    const unsigned char *veto;
    double leak, drift, scale, sigma, gate, tell, level_still, level_max, still_k, start_s;
    double start_within_s, rel, start_sd, like, unlike, unlike_tell, motion, stride;
    long confirm, within, peak_points, mark_every, n_marks;
} acn_kin_fwd;
/*
 * What it says, per candidate i at or after the resumed one: reason[i] (0..3
 * rests.py's ACCEPT_REASONS, 4..7 its REFUSE_REASONS), the evidence's kind
 * base[i] with flags[i] (1: as still as the proven rests, 2: its level moved,
 * a hypothesis, 4: a side within tell that the bound for a short piece far less
 * still than the proven rests refused) and figures num + ACN_KIN_NUM i (the
 * level's jump, the jump allowed, the peak speed since the last rest, the
 * largest sd, the stillness bound, the peak and end speed since the last stand,
 * the sd a side had to reach); a hypothesis' outcome[i]
 * (1: refuted by candidate oarg[2 i] of reason oarg[2 i + 1], 2: not borne out
 * within, 3: the record ended, 4: confirmed, its reason before in oarg[2 i + 1]);
 * its side as kin_test's (side + 4 n_axes i; stat + 3 i: chi-square, |v|,
 * rms sd), the event of its last aid aid[i] (-1: none) and whether a fix came
 * fix[i]. acc, proven: the accepted rests and the proven stillness, carried
 * from pass to pass. mark_l (9 longs), mark_d (13 n_axes doubles), mark_ok:
 * n_marks marks. work: 2 m doubles, tried: m bytes, scratch. Returns 0, or -1
 * (nothing done) where a length or an index lies outside its array.
 */
typedef struct {
    int *reason, *base, *flags, *outcome;
    long *oarg;
    double *num, *side, *stat;
    long *aid;
    unsigned char *fix, *acc, *proven;
    long *mark_l;
    double *mark_d;
    unsigned char *mark_ok;
    double *work;
    unsigned char *tried;
} acn_kin_fwd_out;
long acn_kin_forward(const acn_kin_fwd *f, long resume, acn_kin_fwd_out *o);
/*
 * The rest detector's window pass (host/estimate/zupt.py, _detect), over the
 * centred window of w (odd) rows about each row of x (n rows of n_axes), in two
 * kernels so that no per-row figure but the flag is held whole. The sums are
 * numpy's cumsums (in row order, one axis after the other) differenced, stepped
 * row by row from where state (4 doubles an axis) and at (the window each axis'
 * state holds, -1: none; one long an axis) left them, so every figure is the one
 * zupt.py's numpy gave whatever windows were asked for before.
 * acn_rest_centres: centre[k] (n bytes) is 1 where every row of k's window has
 * usable set and the mean over axes of variance / allow[j] is at most var_k, 0
 * where not or where the window leaves the record.
 * acn_rest_span: for the centres lo .. hi - 1 (each window inside the record, no
 * axis' state past lo's window), the window mean per axis into means (hi - lo
 * rows of n_axes) and the variance summed over the axes into wvar (hi - lo).
 * Both return 0, or -1 (nothing written) where a length is out of range.
 */
long acn_rest_centres(long n, int n_axes, const double *x, const unsigned char *usable, long w,
                      const double *allow, double var_k, double *state, long *at,
                      unsigned char *centre);
long acn_rest_span(long n, int n_axes, const double *x, long w, long lo, long hi, double *state,
                   long *at, double *means, double *wvar);
/*
 * The rest detector's record (host/estimate/zupt.py, _prepared), axis j of
 * accel and clipped (n rows of n_axes): ok = not clipped and finite, and x the
 * acceleration minus the model's bias mean eps_mean - c1 powers[k] (powers:
 * phi^k, n of them, numpy's) where ok, 0 elsewhere; into column j of x and ok.
 * Returns 0, or -1 (nothing written) where a length or j is out of range.
 */
long acn_rest_prepare(long n, int n_axes, int j, const double *accel, const unsigned char *clipped,
                      const double *powers, double eps_mean, double c1, double *x,
                      unsigned char *ok);
/* ACN-CDEF-END */

#endif
