/*
 * Float64 filter and RTS smoother of one accelnav axis: see fastsmooth.h for
 * the conventions and host/fastsmooth.py for the derivation of the plain path.
 *
 * Every block carries the equation it computes, as in host/kf.py.
 */
#include "fastsmooth.h"

#include <limits.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

/* Index of (i, j) in a packed symmetric 4x4 matrix. */
static const int PK[4][4] = {{0, 1, 2, 3}, {1, 4, 5, 6}, {2, 5, 7, 8}, {3, 6, 8, 9}};

static void unpack(const double *p, double M[4][4])
{
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            M[i][j] = p[PK[i][j]];
}

static void pack(double M[4][4], double *p)
{
    for (int i = 0; i < 4; i++)
        for (int j = i; j < 4; j++)
            p[PK[i][j]] = M[i][j];
}

static void transition(const acn_axis *m, double F[4][4])
{
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            F[i][j] = (i == j) ? 1.0 : 0.0;
    F[0][1] = m->f01;
    F[0][2] = m->f02;
    F[1][2] = m->f12;
    F[3][3] = m->phi;
}

/* P = F P F' + Q, with F = [[1, f01, f02, 0], [0, 1, f12, 0], [0, 0, 1, 0], [0, 0, 0, phi]] */
static void predict_cov(const acn_axis *m, double F[4][4], double P[4][4])
{
    const double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi;
    double G[4][4]; /* G = F P */
    (void)F;
    for (int j = 0; j < 4; j++) {
        G[0][j] = P[0][j] + f01 * P[1][j] + f02 * P[2][j];
        G[1][j] = P[1][j] + f12 * P[2][j];
        G[2][j] = P[2][j];
        G[3][j] = phi * P[3][j];
    }
    for (int i = 0; i < 4; i++) { /* P = G F' + Q, upper triangle then mirrored */
        double g0 = G[i][0] + f01 * G[i][1] + f02 * G[i][2];
        double g1 = G[i][1] + f12 * G[i][2];
        double row[4] = {g0, g1, G[i][2], phi * G[i][3]};
        for (int j = i; j < 4; j++)
            P[i][j] = row[j] + m->q[PK[i][j]];
    }
    for (int i = 1; i < 4; i++)
        for (int j = 0; j < i; j++)
            P[i][j] = P[j][i];
}

/*
 * The r and u rows of P = F P F' + Q alone (rows 0, 1 and their mirror), by the
 * very operations of predict_cov: where the (a, eps) block comes from stored
 * rows, the rest of predict_cov was computed only to be overwritten.
 */
static void predict_ru(const acn_axis *m, double P[4][4])
{
    const double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi;
    double G[2][4]; /* rows 0, 1 of G = F P */
    for (int j = 0; j < 4; j++) {
        G[0][j] = P[0][j] + f01 * P[1][j] + f02 * P[2][j];
        G[1][j] = P[1][j] + f12 * P[2][j];
    }
    for (int i = 0; i < 2; i++) {
        double g0 = G[i][0] + f01 * G[i][1] + f02 * G[i][2];
        double g1 = G[i][1] + f12 * G[i][2];
        double row[4] = {g0, g1, G[i][2], phi * G[i][3]};
        for (int j = i; j < 4; j++)
            P[i][j] = row[j] + m->q[PK[i][j]];
    }
    for (int i = 0; i < 2; i++)
        for (int j = i + 1; j < 4; j++)
            P[j][i] = P[i][j];
}

/* x = F x + b */
static void predict_mean(const acn_axis *m, double x[4])
{
    x[0] = x[0] + m->f01 * x[1] + m->f02 * x[2];
    x[1] = x[1] + m->f12 * x[2];
    x[3] = m->phi * x[3] + m->b_eps;
}

/*
 * One scalar update z = h x + v, v ~ N(0, R), Joseph form. Writes K.
 * Returns the innovation y; *S gets its variance.
 */
static double update(double x[4], double P[4][4], const double h[4], double z, double R, double *S,
                     double K[4])
{
    double PHt[4], IKH_P[4][4], hIKH_P[4];
    /* y = z - H x */
    double y = z - (h[0] * x[0] + h[1] * x[1] + h[2] * x[2] + h[3] * x[3]);
    /* S = H P H' + R */
    for (int i = 0; i < 4; i++)
        PHt[i] = P[i][0] * h[0] + P[i][1] * h[1] + P[i][2] * h[2] + P[i][3] * h[3];
    double s = h[0] * PHt[0] + h[1] * PHt[1] + h[2] * PHt[2] + h[3] * PHt[3] + R;
    /* K = P H' / S;  x = x + K y */
    for (int i = 0; i < 4; i++) {
        K[i] = PHt[i] / s;
        x[i] += K[i] * y;
    }
    /* P = (I - K H) P (I - K H)' + K R K'   (P H' = PHt, P symmetric) */
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            IKH_P[i][j] = P[i][j] - K[i] * PHt[j];
    for (int i = 0; i < 4; i++)
        hIKH_P[i] =
            IKH_P[i][0] * h[0] + IKH_P[i][1] * h[1] + IKH_P[i][2] * h[2] + IKH_P[i][3] * h[3];
    for (int i = 0; i < 4; i++)
        for (int j = i; j < 4; j++) {
            P[i][j] = IKH_P[i][j] - hIKH_P[i] * K[j] + R * K[i] * K[j];
            P[j][i] = P[i][j];
        }
    *S = s;
    return y;
}

static const double H_ACC[4] = {0.0, 0.0, 1.0, 1.0};

/* ------------------------------------------------------------------------- */
/* Plain path, data-independent part: gains, covariances, smoother gains.      */

static int plain_smooth_cov(const acn_axis *m, long n, double *Cs, long stride, long ncs,
                            int write_cs, const double *Pprior, const double *Ppost, double *Psm);

int acn_plain_cov(const acn_axis *m, long n, const unsigned char *valid, double *K, double *Cs,
                  double *Pprior, double *Ppost, double *Psm)
{
    double F[4][4], P[4][4], x[4] = {0.0, 0.0, 0.0, 0.0}, S;
    transition(m, F);
    unpack(m->p0, P);

    /* Forward: the 4-state covariance filter; K[k] = 0 where sample k is skipped. */
    for (long k = 0; k < n; k++) {
        double *Kk = K + 4 * k;
        if (k > 0)
            predict_cov(m, F, P);
        pack(P, Pprior + 10 * k);
        if (valid == NULL || valid[k]) {
            update(x, P, H_ACC, 0.0, m->R, &S, Kk);
        } else {
            Kk[0] = Kk[1] = Kk[2] = Kk[3] = 0.0;
        }
        pack(P, Ppost + 10 * k);
    }

    return plain_smooth_cov(m, n, Cs, 4, n, 1, Pprior, Ppost, Psm);
}

/*
 * The forward rows of an all-valid run, ACN_SROW doubles per sample k:
 *   0..3 K[k]   4..7 C[k] (0 at the last sample)   8..10 prior aa ae ee   11..13 posterior aa ae ee
 * the numbers acn_plain_cov computes, none of which depends on the run's length.
 */
int acn_plain_rows(const acn_axis *m, long n, double *rows)
{
    double F[4][4], P[4][4], x[4] = {0.0, 0.0, 0.0, 0.0}, S;
    const double phi = m->phi;
    transition(m, F);
    unpack(m->p0, P);
    for (long k = 0; k < n; k++) {
        double *row = rows + ACN_SROW * k;
        if (k > 0)
            predict_cov(m, F, P);
        row[8] = P[2][2], row[9] = P[2][3], row[10] = P[3][3];
        if (k > 0) { /* C[k-1] = Pf[k-1] Fs' inv(Pp[k]), as in acn_plain_cov */
            double *prev = row - ACN_SROW;
            double paa = prev[11], pae = prev[12], pee = prev[13];
            double qaa = row[8], qae = row[9], qee = row[10];
            double sa = sqrt(qaa), se = sqrt(qee);
            double rho = qae / (sa * se);
            double det = (1.0 - rho * rho) * qaa * qee;
            if (!(det > 0.0))
                return -(int)(k > 1000000000L ? 1000000000L : k);
            double m00 = paa, m01 = phi * pae, m10 = pae, m11 = phi * pee;
            prev[4] = (m00 * qee - m01 * qae) / det, prev[5] = (m01 * qaa - m00 * qae) / det;
            prev[6] = (m10 * qee - m11 * qae) / det, prev[7] = (m11 * qaa - m10 * qae) / det;
        }
        update(x, P, H_ACC, 0.0, m->R, &S, row);
        row[11] = P[2][2], row[12] = P[2][3], row[13] = P[3][3];
    }
    double *lastrow = rows + ACN_SROW * (n - 1);
    lastrow[4] = lastrow[5] = lastrow[6] = lastrow[7] = 0.0;
    return 0;
}

/*
 * The acceleration update of P with a stored steady row (K in row[0..3], the
 * posterior's (a, eps) block in row[11..13]): the r, u rows by
 * P -= K PH' + PH K' - K K' S, with S = H P H' + R (H = [0 0 1 1]).
 */
static void steady_update(double P[4][4], const double *row, double R)
{
    double PHt[4];
    double S = P[2][2] + 2.0 * P[2][3] + P[3][3] + R;
    for (int i = 0; i < 4; i++)
        PHt[i] = P[i][2] + P[i][3];
    for (int i = 0; i < 2; i++)
        for (int j = i; j < 4; j++) {
            P[i][j] -= row[i] * PHt[j] + PHt[i] * row[j] - row[i] * row[j] * S;
            P[j][i] = P[i][j];
        }
    P[2][2] = row[11], P[2][3] = P[3][2] = row[12], P[3][3] = row[13];
}

/*
 * acn_plain_cov of an all-valid run from the rows of acn_plain_rows: sample k
 * reads row min(k, nt - 1), the last stored row being steady (the caller checks
 * that). The (a, eps) blocks come from the rows; the r, u rows of P (which never
 * settle: r, u are not observable) are propagated with the row's gain,
 *   P = F P F' + Q;  P_ij -= K_i (P H')_j + (P H')_i K_j - K_i K_j S   (i in r, u)
 * which is the Joseph update expanded (K = P H' / S). No 4x4 Joseph update per
 * sample: what made acn_plain_cov the largest cost of a run.
 */
int acn_plain_cov_steady(const acn_axis *m, long n, long nt, const double *rows, double *Pprior,
                         double *Ppost, double *Psm)
{
    double F[4][4], P[4][4];
    transition(m, F);
    unpack(m->p0, P);
    for (long k = 0; k < n; k++) {
        const double *row = rows + ACN_SROW * (k < nt ? k : nt - 1);
        if (k > 0)
            predict_cov(m, F, P);
        P[2][2] = row[8], P[2][3] = P[3][2] = row[9], P[3][3] = row[10];
        pack(P, Pprior + 10 * k);
        steady_update(P, row, m->R);
        pack(P, Ppost + 10 * k);
    }
    return plain_smooth_cov(m, n, (double *)rows + 4, ACN_SROW, nt, 0, Pprior, Ppost, Psm);
}

/*
 * The covariance part of one step of the smoothed r, u recursion (see
 * plain_smooth_cov): from P_rr, P_ru, P_ra, P_uu, P_ua, P_aa of sample k
 * (s[0..5]), beta = (beta_r, beta_u) of k (updated to k + 1 in place), the
 * smoother gain C[k] and P_aa, P_ae of sample k + 1, the new P_rr, P_uu, P_ru
 * (out[0..2]).
 */
static inline void ru_cov_step(const acn_axis *m, const double s[6], double beta[4],
                               const double *C, double aa1, double ae1, double out[3])
{
    const double gr = m->gr, gu = m->gu, f01 = m->f01;
    const double c2r = m->f02 - gr, c2u = m->f12 - gu;
    const double qe_rr = m->q[0] - gr * m->q[2], qe_ru = m->q[1] - gr * m->q[5];
    const double qe_uu = m->q[4] - gu * m->q[5];
    double rr = s[0], ru = s[1], ra = s[2], uu = s[3], ua = s[4], aa = s[5];
    double br0 = beta[0], br1 = beta[1], bu0 = beta[2], bu1 = beta[3];
    /* Var and Cov of p_r, p_u (time-k quantities) */
    double vpr =
        rr + f01 * f01 * uu + c2r * c2r * aa + 2.0 * (f01 * ru + c2r * ra + f01 * c2r * ua);
    double vpu = uu + c2u * c2u * aa + 2.0 * c2u * ua;
    double cpp = ru + c2u * ra + f01 * uu + f01 * c2u * ua + c2r * ua + c2r * c2u * aa;
    /* beta of p_r, p_u at k, then mapped to k+1: gamma = C' beta */
    double pr0 = br0 + f01 * bu0 + c2r, pr1 = br1 + f01 * bu1;
    double pu0 = bu0 + c2u, pu1 = bu1;
    double gr0 = C[0] * pr0 + C[2] * pr1, gr1 = C[1] * pr0 + C[3] * pr1;
    double gu0 = C[0] * pu0 + C[2] * pu1, gu1 = C[1] * pu0 + C[3] * pu1;
    double cra = gr0 * aa1 + gr1 * ae1, cua = gu0 * aa1 + gu1 * ae1; /* Cov(p, a~') */
    beta[0] = gr0 + gr, beta[1] = gr1;
    beta[2] = gu0 + gu, beta[3] = gu1;
    /* Var(r~'), Var(u~'), Cov(r~', u~') */
    out[0] = vpr + 2.0 * gr * cra + gr * gr * aa1 + qe_rr;
    out[1] = vpu + 2.0 * gu * cua + gu * gu * aa1 + qe_uu;
    out[2] = cpp + gu * cra + gr * cua + gr * gu * aa1 + qe_ru;
}

/*
 * The smoother's covariances from the filter's (Pprior, Ppost): the (a, eps)
 * block backward, then the r, u rows forward. The smoother gain of sample k is
 * computed backward (written to Cs[k] if write_cs) and read forward from row
 * min(k, ncs - 1) of Cs, rows stride doubles apart (ncs < n: a stored
 * transient whose last row is steady).
 */
static int plain_smooth_cov(const acn_axis *m, long n, double *Cs, long stride, long ncs,
                            int write_cs, const double *Pprior, const double *Ppost, double *Psm)
{
    /* Backward: the 2-state RTS smoother of s = (a, eps), Fs = diag(1, phi). */
    const double phi = m->phi;
    double *last = Psm + 10 * (n - 1);
    for (int i = 0; i < 10; i++)
        last[i] = Ppost[10 * (n - 1) + i];
    if (write_cs)
        Cs[stride * (n - 1) + 0] = Cs[stride * (n - 1) + 1] = Cs[stride * (n - 1) + 2] =
            Cs[stride * (n - 1) + 3] = 0.0;
    for (long k = n - 2; k >= 0; k--) {
        const double *pf = Ppost + 10 * k, *pp = Pprior + 10 * (k + 1), *s1 = Psm + 10 * (k + 1);
        double *ps = Psm + 10 * k;
        double paa = pf[7], pae = pf[8], pee = pf[9];
        double qaa = pp[7], qae = pp[8], qee = pp[9];
        /* C = Pf Fs' inv(Pp), inv(Pp) = [qee, -qae; -qae, qaa] / det, det on the equilibrated Pp */
        double sa = sqrt(qaa), se = sqrt(qee);
        double rho = qae / (sa * se);
        double det = (1.0 - rho * rho) * qaa * qee;
        if (!(det > 0.0))
            return -(int)(k + 1 > 1000000000L ? 1000000000L : k + 1);
        double m00 = paa, m01 = phi * pae, m10 = pae, m11 = phi * pee; /* Pf Fs' */
        double c00 = (m00 * qee - m01 * qae) / det, c01 = (m01 * qaa - m00 * qae) / det;
        double c10 = (m10 * qee - m11 * qae) / det, c11 = (m11 * qaa - m10 * qae) / det;
        if (write_cs)
            Cs[stride * k + 0] = c00, Cs[stride * k + 1] = c01, Cs[stride * k + 2] = c10,
                            Cs[stride * k + 3] = c11;
        /* Ps = Pf + C (Ps[k+1] - Pp) C' */
        double daa = s1[7] - qaa, dae = s1[8] - qae, dee = s1[9] - qee;
        double t00 = c00 * daa + c01 * dae, t01 = c00 * dae + c01 * dee;
        double t10 = c10 * daa + c11 * dae, t11 = c10 * dae + c11 * dee;
        ps[7] = paa + t00 * c00 + t01 * c01;
        ps[8] = pae + t00 * c10 + t01 * c11;
        ps[9] = pee + t10 * c10 + t11 * c11;
    }

    /*
     * Forward: the r, u rows of the smoothed covariance. With s~ the smoothing
     * error of s, Cov(x~_k, s~_j) = beta_x' Cov(s~_k, s~_j) for every j >= k;
     * moving to k+1 maps beta to Cs[k]' beta (Cov(s~_k, s~_j) = C_k Cov(s~_k+1, s~_j)).
     *   u~' = p_u + gu a~' + e_u,   p_u = u~ + (f12 - gu) a~
     *   r~' = p_r + gr a~' + e_r,   p_r = r~ + f01 u~ + (f02 - gr) a~
     * e = (e_r, e_u) is the part of w_(r,u) independent of w_a, covariance Qe.
     */
    double beta[4] = {0.0, 0.0, 0.0, 0.0};
    {
        double *ps = Psm + 0;
        const double *pf = Ppost + 0;
        if (n > 1) { /* r, u of sample 0 are independent of every measurement */
            ps[0] = pf[0], ps[1] = pf[1], ps[4] = pf[4];
            ps[2] = ps[3] = ps[5] = ps[6] = 0.0;
        }
    }
    for (long k = 0; k + 1 < n; k++) {
        const double *p = Psm + 10 * k, *C = Cs + stride * (k < ncs ? k : ncs - 1);
        double *q = Psm + 10 * (k + 1);
        const double s[6] = {p[0], p[1], p[2], p[4], p[5], p[7]};
        double aa1 = q[7], ae1 = q[8], ee1 = q[9], out[3];
        ru_cov_step(m, s, beta, C, aa1, ae1, out);
        q[0] = out[0], q[4] = out[1], q[1] = out[2];
        /* Cov(r~', s~') = beta_r' Ps_s, Cov(u~', s~') = beta_u' Ps_s */
        q[2] = beta[0] * aa1 + beta[1] * ae1, q[3] = beta[0] * ae1 + beta[1] * ee1;
        q[5] = beta[2] * aa1 + beta[3] * ae1, q[6] = beta[2] * ae1 + beta[3] * ee1;
    }
    /* the smoother's last sample is the filter's, exactly (the reference's convention) */
    for (int i = 0; i < 10; i++)
        last[i] = Ppost[10 * (n - 1) + i];
    return 0;
}

/* ------------------------------------------------------------------------- */
/* Plain path, data pass: filter means with the precomputed gains, the (a, eps) */
/* RTS means, then r, u of the smoother in closed form.                        */

void acn_plain_data(const acn_axis *m, long n, const double *z, const unsigned char *valid,
                    const double *K, const double *Cs, long stride, long nk, double *xf, double *xs)
{
    const double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi, b = m->b_eps;
    const double gr = m->gr, gu = m->gu;
    double r = m->x0[0], u = m->x0[1], a = m->x0[2], e = m->x0[3];

    /*
     * x = F x + b, then y = z - (a + eps), x = x + K y. Written so that the
     * loop-carried chain through (a, eps) is short: with ep = phi eps + b,
     *   a'   = (1 - Ka) a - Ka ep + Ka z
     *   eps' = -Ke a + (1 - Ke) ep + Ke z
     * (the same numbers up to rounding).
     */
    for (long k = 0; k < n; k++) {
        const double *Kk = K + stride * (k < nk ? k : nk - 1); /* steady after row nk - 1 */
        double ep = e;
        if (k > 0) {
            r = r + f01 * u + f02 * a;
            u = u + f12 * a;
            ep = phi * e + b;
        }
        if (valid == NULL || valid[k]) {
            double y = z[k] - a - ep;
            r += Kk[0] * y;
            u += Kk[1] * y;
            double ka = Kk[2], ke = Kk[3], zk = z[k];
            double an = (a - ka * a) + ka * (zk - ep);
            e = (ep - ke * ep) + ke * (zk - a);
            a = an;
        } else {
            e = ep;
        }
        double *o = xf + 4 * k;
        o[0] = r, o[1] = u, o[2] = a, o[3] = e;
    }

    /* s[k] = s_post[k] + C[k] (s[k+1] - Fs s_post[k] - b),  s = (a, eps) */
    double as = xf[4 * (n - 1) + 2], es = xf[4 * (n - 1) + 3];
    xs[4 * (n - 1) + 2] = as, xs[4 * (n - 1) + 3] = es;
    for (long k = n - 2; k >= 0; k--) {
        const double *f = xf + 4 * k, *C = Cs + stride * (k < nk ? k : nk - 1);
        /* = C s[k+1] + (s_post[k] - C (Fs s_post[k] + b)): the chain through s is one mul-add */
        double fa = f[2], fe = phi * f[3] + b;
        double ca = f[2] - (C[0] * fa + C[1] * fe), ce = f[3] - (C[2] * fa + C[3] * fe);
        double an = C[0] * as + C[1] * es + ca;
        es = C[2] * as + C[3] * es + ce;
        as = an;
        xs[4 * k + 2] = as, xs[4 * k + 3] = es;
    }

    /* u[k+1] = u[k] + f12 a[k] + gu (a[k+1] - a[k]);  r likewise, from r[0], u[0] of the filter */
    r = xf[0], u = xf[1];
    xs[0] = r, xs[1] = u;
    for (long k = 0; k + 1 < n; k++) {
        double a0 = xs[4 * k + 2], a1 = xs[4 * k + 6];
        double dw = a1 - a0;
        r = r + (f01 * u + (f02 * a0 + gr * dw));
        u = u + (f12 * a0 + gu * dw);
        xs[4 * k + 4] = r, xs[4 * k + 5] = u;
    }
    xs[4 * (n - 1) + 0] = xf[4 * (n - 1) + 0]; /* the smoother's last sample is the filter's */
    xs[4 * (n - 1) + 1] = xf[4 * (n - 1) + 1];
}

/* ------------------------------------------------------------------------- */
/* General path: 4-state filter with extras, 4-state RTS smoother.            */
/*                                                                            */
/* Per sample this path once cost about 1.2 us per axis: full 4x4 products,    */
/* a packed/unpacked copy of every matrix and an equilibrated Cholesky with    */
/* some 70 divisions and 8 square roots. Here the same equations act on the    */
/* packed P (10 numbers) with F written out (r, u integrate; a holds; eps      */
/* decays): the filter does the very operations of the 4x4 code in the same    */
/* order, minus those whose operand is an exact 0 or 1, so its numbers are     */
/* bit-identical; only the smoother gain's solve rounds differently.          */

/* Names of the packed entries (fastsmooth.h). */
enum { RR, RU, RA, RE, UU, UA, UE, AA, AE, EE };

/* B = F P, all 16 entries (rows 2 and 3 are P's own, the last scaled by phi). */
static inline void fp_rows(const acn_axis *m, const double *p, double B[4][4])
{
    const double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi;
    const double P0[4] = {p[RR], p[RU], p[RA], p[RE]}, P1[4] = {p[RU], p[UU], p[UA], p[UE]};
    const double P2[4] = {p[RA], p[UA], p[AA], p[AE]}, P3[4] = {p[RE], p[UE], p[AE], p[EE]};
    for (int j = 0; j < 4; j++) {
        B[0][j] = P0[j] + f01 * P1[j] + f02 * P2[j];
        B[1][j] = P1[j] + f12 * P2[j];
        B[2][j] = P2[j];
        B[3][j] = phi * P3[j];
    }
}

/* P = B F' + Q with B = F P: the upper triangle of predict_cov's second half. */
static inline void predict_packed(const acn_axis *m, double B[4][4], double *p)
{
    const double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi;
    const double *q = m->q;
    p[RR] = B[0][0] + f01 * B[0][1] + f02 * B[0][2] + q[RR];
    p[RU] = B[0][1] + f12 * B[0][2] + q[RU];
    p[RA] = B[0][2] + q[RA];
    p[RE] = phi * B[0][3] + q[RE];
    p[UU] = B[1][1] + f12 * B[1][2] + q[UU];
    p[UA] = B[1][2] + q[UA];
    p[UE] = phi * B[1][3] + q[UE];
    p[AA] = B[2][2] + q[AA];
    p[AE] = phi * B[2][3] + q[AE];
    p[EE] = phi * B[3][3] + q[EE];
}

/* P = F P F' + Q on the packed P */
static inline void predict_p(const acn_axis *m, double *p)
{
    double B[4][4];
    fp_rows(m, p, B);
    predict_packed(m, B, p);
}

/*
 * One scalar update z = h x + v, v ~ N(0, R), Joseph form, on the packed P.
 * nz lists the nn indices where h is not 0 (ascending): a term h_j P_ij with
 * h_j = 0 adds an exact 0, so the sums over nz alone are update()'s sums to the
 * bit. Returns the innovation y; *S gets its variance.
 */
static inline double update_sparse(double x[4], double *p, const double h[4], const int *nz, int nn,
                                   double z, double R, double *S)
{
    double PHt[4], K[4], hI[4], hx = 0.0, s = 0.0;
    /* y = z - H x */
    for (int t = 0; t < nn; t++)
        hx = t ? hx + h[nz[t]] * x[nz[t]] : h[nz[t]] * x[nz[t]];
    double y = z - hx;
    /* S = H P H' + R */
    for (int i = 0; i < 4; i++) {
        double v = 0.0;
        for (int t = 0; t < nn; t++)
            v = t ? v + p[PK[i][nz[t]]] * h[nz[t]] : p[PK[i][nz[t]]] * h[nz[t]];
        PHt[i] = v;
    }
    for (int t = 0; t < nn; t++)
        s = t ? s + h[nz[t]] * PHt[nz[t]] : h[nz[t]] * PHt[nz[t]];
    s += R;
    /* K = P H' / S;  x = x + K y */
    for (int i = 0; i < 4; i++) {
        K[i] = PHt[i] / s;
        x[i] += K[i] * y;
    }
    /* P = (I - K H) P (I - K H)' + K R K':  with IKH_P = P - K PHt', hI = IKH_P H' */
    for (int i = 0; i < 4; i++) {
        double v = 0.0;
        for (int t = 0; t < nn; t++) {
            int c = nz[t];
            double w = (p[PK[i][c]] - K[i] * PHt[c]) * h[c];
            v = t ? v + w : w;
        }
        hI[i] = v;
    }
    for (int i = 0; i < 4; i++)
        for (int j = i; j < 4; j++) {
            double *pij = p + PK[i][j];
            *pij = (*pij - K[i] * PHt[j]) - hI[i] * K[j] + R * K[i] * K[j];
        }
    *S = s;
    return y;
}

static const int NZ_ACC[2] = {2, 3};
static const double H_UNIT[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};
static const int NZ_UNIT[4][1] = {{0}, {1}, {2}, {3}};

/*
 * An aid's update: a rest (h = e_u) or a fix (h = e_r) with h and nz as
 * constants, so that the compiler unrolls update_sparse for them (same numbers:
 * h[c] is exactly 1 there); any other h through the general loop.
 */
static double update_aid(double x[4], double *p, const double h[4], const int *nz, int nn, double z,
                         double R, double *S)
{
    if (nn == 1 && h[nz[0]] == 1.0) {
        switch (nz[0]) {
        case 0:
            return update_sparse(x, p, H_UNIT[0], NZ_UNIT[0], 1, z, R, S);
        case 1:
            return update_sparse(x, p, H_UNIT[1], NZ_UNIT[1], 1, z, R, S);
        case 2:
            return update_sparse(x, p, H_UNIT[2], NZ_UNIT[2], 1, z, R, S);
        default:
            return update_sparse(x, p, H_UNIT[3], NZ_UNIT[3], 1, z, R, S);
        }
    }
    return update_sparse(x, p, h, nz, nn, z, R, S);
}

/*
 * The measurements of sample k once its prior is in (x, p): the acceleration
 * if ok, then the extras ek[ei] == k in order. Returns the index of the first
 * extra of a later sample. ey, eS (or NULL) get each extra's innovation y and
 * its variance S as the filter saw them: y^2 / S is the aid's NIS, with no
 * replay of the filter (accelnav.estimate.consistency). A sample with neither
 * is left alone: its posterior is its prior.
 */
static long general_update(const acn_axis *m, long k, int ok, double zk, double x[4], double *p,
                           long ei, long n_extra, const long *ek, const double *eh,
                           const double *ez, const double *eR, const double *egate,
                           unsigned char *applied, double *ey, double *eS)
{
    double S;
    if (ok)
        update_sparse(x, p, H_ACC, NZ_ACC, 2, zk, m->R, &S);
    for (; ei < n_extra && ek[ei] == k; ei++) {
        const double *h = eh + 4 * ei;
        int nz[4], nn = 0; /* fixes and rests have one or two nonzeros in h */
        for (int j = 0; j < 4; j++)
            if (h[j] != 0.0)
                nz[nn++] = j;
        if (egate[ei] > 0.0) {
            /* gated: apply only if y^2 / S <= gate (a chi-square test of the innovation) */
            double hx = 0.0;
            for (int t = 0; t < nn; t++)
                hx = t ? hx + h[nz[t]] * x[nz[t]] : h[nz[t]] * x[nz[t]];
            double y = ez[ei] - hx;
            double s = eR[ei];
            for (int a = 0; a < nn; a++)
                for (int b = 0; b < nn; b++)
                    s += h[nz[a]] * p[PK[nz[a]][nz[b]]] * h[nz[b]];
            if (y * y > egate[ei] * s) {
                applied[ei] = 0;
                if (ey != NULL) {
                    ey[ei] = y;
                    eS[ei] = s;
                }
                continue;
            }
        }
        double y = update_aid(x, p, h, nz, nn, ez[ei], eR[ei], &S);
        applied[ei] = 1;
        if (ey != NULL) {
            ey[ei] = y;
            eS[ei] = S;
        }
    }
    return ei;
}

/* Solve M Y = B for symmetric positive definite 4x4 M (Cholesky), B 4x4. */
static int chol_solve4(double M[4][4], double B[4][4])
{
    double L[4][4] = {{0.0}};
    for (int j = 0; j < 4; j++) {
        double d = M[j][j];
        for (int l = 0; l < j; l++)
            d -= L[j][l] * L[j][l];
        if (!(d > 0.0))
            return -1;
        L[j][j] = sqrt(d);
        for (int i = j + 1; i < 4; i++) {
            double s = M[i][j];
            for (int l = 0; l < j; l++)
                s -= L[i][l] * L[j][l];
            L[i][j] = s / L[j][j];
        }
    }
    for (int c = 0; c < 4; c++) {
        for (int i = 0; i < 4; i++) { /* L y = b */
            double s = B[i][c];
            for (int l = 0; l < i; l++)
                s -= L[i][l] * B[l][c];
            B[i][c] = s / L[i][i];
        }
        for (int i = 3; i >= 0; i--) { /* L' x = y */
            double s = B[i][c];
            for (int l = i + 1; l < 4; l++)
                s -= L[l][i] * B[l][c];
            B[i][c] = s / L[i][i];
        }
    }
    return 0;
}

/*
 * The fallback gain C = Pf F' inv(Pp) by the former route: Cholesky of the
 * equilibrated Pp (unit diagonal), into Ct (C transposed). Returns -1 if Pp is
 * not positive definite.
 */
static int gain_equilibrated(const double *pp, double B[4][4], double Ct[4][4])
{
    double Pp[4][4], Mq[4][4], sd[4];
    unpack(pp, Pp);
    for (int i = 0; i < 4; i++)
        sd[i] = Pp[i][i] > 0.0 ? sqrt(Pp[i][i]) : 1.0;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            B[i][j] /= sd[i];
            Mq[i][j] = Pp[i][j] / (sd[i] * sd[j]);
        }
    if (chol_solve4(Mq, B) != 0)
        return -1;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            Ct[i][j] = B[i][j] / sd[i];
    return 0;
}

/*
 * The smoother gain C = Pf F' inv(Pp), i.e. C' = inv(Pp) B with B = F Pf:
 * Pp = L D L' (unit lower L) unrolled, four reciprocals and no square root,
 * then four forward and back substitutions. Eliminating r, u first is the block
 * form: (a, eps) are left with the Schur complement of the (r, u) block. No
 * equilibration: LDL' of an SPD matrix is invariant to diagonal scaling up to
 * rounding (what the former sqrt(diag) scaling bought was eight square roots
 * and 32 divisions). Against the recursion in extended precision this solve
 * is the closer of the two (tests/estimate/test_general_structured.py).
 * Guarded fallback: when a pivot keeps under 1e-12 of its diagonal (r and u, or
 * a and eps, nearly collinear: most digits cancelled) or is not positive, the
 * former equilibrated Cholesky decides that step, and its refusal stands when
 * the prior is not positive definite. Both routes are inaccurate on so
 * ill-conditioned a prior; the fallback keeps the former behaviour there.
 */
typedef struct {
    double i0, l10, l20, l30, i1, l21, l31, i2, l32, i3;
    int ok; /* every pivot passed the guard */
} ldl4;

/* The LDL' factors of the packed prior pp (reciprocal pivots), all computed; ok says whether the
   guard lets them decide */
static inline void ldl_factor(const double *pp, ldl4 *f)
{
    const double tol = 1e-12;
    const double a00 = pp[RR], a10 = pp[RU], a20 = pp[RA], a30 = pp[RE];
    f->ok = a00 > 0.0;
    f->i0 = 1.0 / a00;
    f->l10 = a10 * f->i0, f->l20 = a20 * f->i0, f->l30 = a30 * f->i0;
    double d1 = pp[UU] - f->l10 * a10;
    f->ok = f->ok && d1 > tol * pp[UU];
    f->i1 = 1.0 / d1;
    double t21 = pp[UA] - f->l20 * a10, t31 = pp[UE] - f->l30 * a10; /* L21 d1, L31 d1 */
    f->l21 = t21 * f->i1, f->l31 = t31 * f->i1;
    double d2 = pp[AA] - f->l20 * a20 - f->l21 * t21;
    f->ok = f->ok && d2 > tol * pp[AA];
    f->i2 = 1.0 / d2;
    double t32 = pp[AE] - f->l30 * a20 - f->l31 * t21; /* L32 d2 */
    f->l32 = t32 * f->i2;
    double d3 = pp[EE] - f->l30 * a30 - f->l31 * t31 - f->l32 * t32;
    f->ok = f->ok && d3 > tol * pp[EE];
    f->i3 = 1.0 / d3;
}

/* L y = b, then L' x = y / d, the four columns c of B side by side (each step the same operations
   on each column, so a compiler may take two or four at once): x_i[c] is C[c][i], i.e. row i of Ct
 */
static inline void ldl_solve(const ldl4 *f, double B[4][4], double Ct[4][4])
{
    double y1[4], y2[4], y3[4];
    for (int c = 0; c < 4; c++)
        y1[c] = B[1][c] - f->l10 * B[0][c];
    for (int c = 0; c < 4; c++)
        y2[c] = B[2][c] - f->l20 * B[0][c] - f->l21 * y1[c];
    for (int c = 0; c < 4; c++)
        y3[c] = B[3][c] - f->l30 * B[0][c] - f->l31 * y1[c] - f->l32 * y2[c];
    for (int c = 0; c < 4; c++)
        Ct[3][c] = y3[c] * f->i3;
    for (int c = 0; c < 4; c++)
        Ct[2][c] = y2[c] * f->i2 - f->l32 * Ct[3][c];
    for (int c = 0; c < 4; c++)
        Ct[1][c] = y1[c] * f->i1 - f->l21 * Ct[2][c] - f->l31 * Ct[3][c];
    for (int c = 0; c < 4; c++)
        Ct[0][c] = B[0][c] * f->i0 - f->l10 * Ct[1][c] - f->l20 * Ct[2][c] - f->l30 * Ct[3][c];
}

static int smoother_gain(const double *pp, double B[4][4], double Ct[4][4])
{
    ldl4 f;
    ldl_factor(pp, &f);
    if (!f.ok)
        return gain_equilibrated(pp, B, Ct);
    ldl_solve(&f, B, Ct);
    return 0;
}

static void rts_apply(double Ct[4][4], const double *xpost, const double *pf, const double *xprior1,
                      const double *pp, const double *xs1, const double *ps1, double *xs,
                      double *psm)
{
    double dx[4], D[4][4], T[4][4]; /* Ct[l][i] = C[i][l] */
    /* xs = x_post + C (xs[k+1] - x_prior[k+1]) */
    for (int i = 0; i < 4; i++)
        dx[i] = xs1[i] - xprior1[i];
    for (int i = 0; i < 4; i++)
        xs[i] =
            xpost[i] + Ct[0][i] * dx[0] + Ct[1][i] * dx[1] + Ct[2][i] * dx[2] + Ct[3][i] * dx[3];
    /* Ps = P_post + C (Ps[k+1] - P_prior[k+1]) C', upper triangle */
    for (int i = 0; i < 4; i++)
        for (int j = i; j < 4; j++)
            D[i][j] = D[j][i] = ps1[PK[i][j]] - pp[PK[i][j]];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            T[i][j] =
                Ct[0][i] * D[0][j] + Ct[1][i] * D[1][j] + Ct[2][i] * D[2][j] + Ct[3][i] * D[3][j];
    /* row i of C D C' over all four j (rows of Ct: two at a time), its upper triangle kept: written
       out entry by entry, so that the rows stay in registers (the loop over j >= i read them back
       from memory and looked PK up at run time) */
    double W[4][4];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++)
            W[i][j] =
                T[i][0] * Ct[0][j] + T[i][1] * Ct[1][j] + T[i][2] * Ct[2][j] + T[i][3] * Ct[3][j];
    psm[RR] = pf[RR] + W[0][0], psm[RU] = pf[RU] + W[0][1];
    psm[RA] = pf[RA] + W[0][2], psm[RE] = pf[RE] + W[0][3];
    psm[UU] = pf[UU] + W[1][1], psm[UA] = pf[UA] + W[1][2], psm[UE] = pf[UE] + W[1][3];
    psm[AA] = pf[AA] + W[2][2], psm[AE] = pf[AE] + W[2][3];
    psm[EE] = pf[EE] + W[3][3];
}

/*
 * One RTS step: the smoothed (xs, psm) of sample k from the filter's posterior
 * (xpost, pf) at k, its prior (xprior1, pp) at k + 1 and the smoothed
 * (xs1, ps1) at k + 1; covariances packed. B = F Pf (fp_rows of pf). Returns -1
 * if that prior is not positive definite.
 */
static int rts_step(double B[4][4], const double *xpost, const double *pf, const double *xprior1,
                    const double *pp, const double *xs1, const double *ps1, double *xs, double *psm)
{
    double Ct[4][4];
    if (smoother_gain(pp, B, Ct) != 0)
        return -1;
    rts_apply(Ct, xpost, pf, xprior1, pp, xs1, ps1, xs, psm);
    return 0;
}

int acn_general(const acn_axis *m, long n, const double *z, const unsigned char *valid,
                long n_extra, const long *ek, const double *eh, const double *ez, const double *eR,
                const double *egate, unsigned char *applied, double *ey, double *eS, double *xprior,
                double *Pprior, double *xpost, double *Ppost, double *xs, double *Psm)
{
    double p[10], x[4];
    long ei = 0;
    memcpy(p, m->p0, sizeof p);
    memcpy(x, m->x0, sizeof x);

    for (long k = 0; k < n; k++) {
        if (k > 0) {
            predict_mean(m, x);
            predict_p(m, p);
        }
        memcpy(xprior + 4 * k, x, sizeof x);
        memcpy(Pprior + 10 * k, p, sizeof p);
        ei = general_update(m, k, valid == NULL || valid[k], z[k], x, p, ei, n_extra, ek, eh, ez,
                            eR, egate, applied, ey, eS);
        memcpy(xpost + 4 * k, x, sizeof x);
        memcpy(Ppost + 10 * k, p, sizeof p);
    }

    memcpy(xs + 4 * (n - 1), xpost + 4 * (n - 1), 4 * sizeof(double));
    memcpy(Psm + 10 * (n - 1), Ppost + 10 * (n - 1), 10 * sizeof(double));
    for (long k = n - 2; k >= 0; k--) {
        double B[4][4];
        fp_rows(m, Ppost + 10 * k, B);
        if (rts_step(B, xpost + 4 * k, Ppost + 10 * k, xprior + 4 * (k + 1), Pprior + 10 * (k + 1),
                     xs + 4 * (k + 1), Psm + 10 * (k + 1), xs + 4 * k, Psm + 10 * k) != 0)
            return -(int)(k + 1 > 1000000000L ? 1000000000L : k + 1);
    }
    return 0;
}

/* ------------------------------------------------------------------------- */
/* Rest detector: a run of quiet window centres split into pieces of steady   */
/* level (host/estimate/zupt.py, _steady_pieces: what and why is said there). */
/* The same steps in the same order as numpy takes them there, so the pieces  */
/* are the same numbers: medians are order statistics (the mean of the two    */
/* middle ones for an even count), sums over rows run row by row, sums over   */
/* axes axis by axis (numpy's order for these shapes up to 7 axes; from 8     */
/* numpy sums pairwise, so zupt.py takes at most 7).                          */

/* The k-th smallest of v[0..n-1] (v reordered: v[0..k-1] <= v[k] <= v[k+1..]). */
static double select_kth(double *v, long n, long k)
{
    long lo = 0, hi = n - 1;
    while (hi > lo) {
        double pivot = v[lo + (hi - lo) / 2];
        long i = lo, j = hi;
        while (i <= j) {
            while (v[i] < pivot)
                i++;
            while (v[j] > pivot)
                j--;
            if (i <= j) {
                double t = v[i];
                v[i] = v[j];
                v[j] = t;
                i++;
                j--;
            }
        }
        if (k <= j)
            hi = j;
        else if (k >= i)
            lo = i;
        else
            break;
    }
    return v[k];
}

static void swap_d(double *v, long i, long j)
{
    double t = v[i];
    v[i] = v[j];
    v[j] = t;
}

/* select_kth by Floyd and Rivest's method: the pivot is first brought close to the k-th value by
   selecting within a small sample about it, so each pass over a long range keeps only a sliver of
   it (about 1.5 comparisons a value against quickselect's 3.4). One long rest of 1e6 rows: its
   pieces 0.070 -> 0.039 s, with the second median below reused; the bench's stop-and-go, whose
   items are mostly short, the same. The k-th value is unique, so the median is the same double.
   For a total order only: no NaN in v. */
static void select_fr(double *v, long lo, long hi, long k)
{
    while (hi > lo) {
        if (hi - lo > 600) {
            double n = (double)(hi - lo + 1), i = (double)(k - lo + 1), z = log(n);
            double s = 0.5 * exp(2.0 * z / 3.0);
            double sd = 0.5 * sqrt(z * s * (n - s) / n) * (i - n / 2.0 < 0.0 ? -1.0 : 1.0);
            long l2 = (long)((double)k - i * s / n + sd),
                 h2 = (long)((double)k + (n - i) * s / n + sd);
            select_fr(v, l2 > lo ? l2 : lo, h2 < hi ? h2 : hi, k);
        }
        double t = v[k];
        long i = lo, j = hi;
        swap_d(v, lo, k);
        if (v[hi] > t)
            swap_d(v, hi, lo);
        while (i < j) {
            swap_d(v, i, j);
            i++;
            j--;
            while (v[i] < t)
                i++;
            while (v[j] > t)
                j--;
        }
        if (v[lo] == t) {
            swap_d(v, lo, j);
        } else {
            j++;
            swap_d(v, j, hi);
        }
        if (j <= k)
            lo = j + 1;
        if (k <= j)
            hi = j - 1;
    }
}

/* Per axis, the median of rows a..b-1 of means (n_axes columns), as np.median(means[a:b], axis=0).
 */
static void median_rows(const double *means, int n_axes, long a, long b, double *scratch,
                        double *ref)
{
    long k = b - a, h = k / 2;
    for (int j = 0; j < n_axes; j++) {
        int nan = 0;
        for (long i = 0; i < k; i++) {
            double v = means[(a + i) * n_axes + j];
            nan |= v != v;
            scratch[i] = v;
        }
        double hi;
        if (nan) { /* no order to select in: the steps this always took */
            hi = select_kth(scratch, k, h);
        } else {
            select_fr(scratch, 0, k - 1, h);
            hi = scratch[h];
        }
        if (k % 2) {
            ref[j] = hi;
        } else {
            double lo = scratch[0];
            for (long i = 1; i < h; i++)
                lo = scratch[i] > lo ? scratch[i] : lo;
            ref[j] = (lo + hi) / 2.0;
        }
    }
}

double acn_rest_median(long n, double *v)
{
    if (n < 1)
        return NAN;
    for (long i = 0; i < n; i++)
        if (v[i] != v[i])
            return NAN;
    long h = n / 2;
    select_fr(v, 0, n - 1, h);
    if (n % 2)
        return v[h];
    double lo = v[0];
    for (long i = 1; i < h; i++)
        lo = v[i] > lo ? v[i] : lo;
    return (lo + v[h]) / 2.0; /* np.mean of the two: their sum over 2 */
}

/* sum over axes of (row - ref)^2 */
static double dist2(const double *row, const double *ref, int n_axes)
{
    double s = (row[0] - ref[0]) * (row[0] - ref[0]);
    for (int j = 1; j < n_axes; j++)
        s += (row[j] - ref[j]) * (row[j] - ref[j]);
    return s;
}

long acn_rest_widen(long n, int n_axes, const double *x, const unsigned char *usable, long count,
                    const double *refs, const double *lim2, const long *edge, int step, long h,
                    long *out)
{
    if (n < 0 || count < 0 || h < 0 || n_axes < 1 || n_axes > ACN_REST_MAX_AXES ||
        (step != 1 && step != -1) || n > LONG_MAX / n_axes)
        return -1;
    for (long i = 0; i < count; i++) /* an edge within the record: its steps cannot overflow */
        if (edge[i] < -1 || edge[i] > n)
            return -1;
    for (long i = 0; i < count; i++) {
        long s = 0;
        for (; s < h; s++) {
            long k = edge[i] + step * (s + 1);
            if (k < 0 || k >= n || !usable[k] ||
                !(dist2(x + k * n_axes, refs + i * n_axes, n_axes) <= lim2[i]))
                break;
        }
        out[i] = s;
    }
    return 0;
}

/* Per axis, the mean of rows a..b-1 (b > a). */
static void mean_rows(const double *v, int n_axes, long a, long b, double *out)
{
    for (int j = 0; j < n_axes; j++)
        out[j] = v[a * n_axes + j];
    for (long i = a + 1; i < b; i++)
        for (int j = 0; j < n_axes; j++)
            out[j] += v[i * n_axes + j];
    for (int j = 0; j < n_axes; j++)
        out[j] /= (double)(b - a);
}

typedef struct {
    long a, b;
    int side; /* 0: a part of the run; -1, 1: trimmed off the start, the end of a piece */
    double parent[ACN_REST_MAX_AXES];
} rest_item;

long acn_rest_pieces(long n, int n_axes, const double *means, const double *x, double bound2,
                     double total, long w, double tilt_rate, long lean, double leak_rate,
                     double *scratch, long *pstart, long *pstop, double *pref, double *pown)
{
    if (n < 1)
        return 0;
    if (n_axes < 1 || n_axes > ACN_REST_MAX_AXES)
        return -2;
    /* the items on the stack are disjoint, non-empty ranges of the run: at most n of them, mostly
     * a few; grown as they come (n of them reserved up front was 88 B a row of a long rest). Room
     * for 4 at first, so that every run of more than one piece takes the growing path. */
    long cap = n < 4 ? n : 4;
    rest_item *todo = malloc((size_t)cap * sizeof *todo);
    if (todo == NULL)
        return -1;
    long top = 0, count = 0;
    todo[top].a = 0;
    todo[top].b = n;
    todo[top].side = 0;
    top++;
    double ref[ACN_REST_MAX_AXES], first[ACN_REST_MAX_AXES], last[ACN_REST_MAX_AXES],
        var[ACN_REST_MAX_AXES];
    while (top > 0) {
        rest_item it = todo[--top];
        long a = it.a, b = it.b;
        if (top + 4 > cap && cap < n) { /* room for the (at most 4) parts this item leaves */
            long more = cap * 2 < n ? cap * 2 : n;
            rest_item *grown = realloc(todo, (size_t)more * sizeof *todo);
            if (grown == NULL) {
                free(todo);
                return -1;
            }
            todo = grown;
            cap = more;
        }
        /* the longest stretch within sqrt(bound2) of the median; the parts either side are split
         * again */
        median_rows(means, n_axes, a, b, scratch, ref);
        long best_p = -1, best_len = 0, run = -1;
        for (long i = a; i <= b; i++) {
            int near = i < b && dist2(means + i * n_axes, ref, n_axes) <= bound2;
            if (near && run < 0)
                run = i;
            if (!near && run >= 0) {
                if (i - run > best_len) {
                    best_len = i - run;
                    best_p = run;
                }
                run = -1;
            }
        }
        if (best_p < 0) {
            /* no window near the median (levels spread over a long drive under a drifting tilt):
             * the halves are split on their own rather than the whole stretch lost */
            if (it.side == 0 && b - a >= 2) {
                long h = a + (b - a) / 2;
                todo[top].a = a;
                todo[top].b = h;
                todo[top].side = 0;
                top++;
                todo[top].a = h;
                todo[top].b = b;
                todo[top].side = 0;
                top++;
            }
            continue;
        }
        long p = best_p, q = best_p + best_len;
        if (p > a) {
            todo[top].a = a;
            todo[top].b = p;
            todo[top].side = 0;
            top++;
        }
        if (b > q) {
            todo[top].a = q;
            todo[top].b = b;
            todo[top].side = 0;
            top++;
        }
        /* the ends, once more, against the piece's own noise (the median of the whole item when the
         * stretch is all of it, as a rest's run mostly is: ref holds it) */
        if (p != a || q != b)
            median_rows(means, n_axes, p, q, scratch, ref);
        mean_rows(x, n_axes, p, q, first);
        for (int j = 0; j < n_axes; j++)
            var[j] = 0.0;
        for (long i = p; i < q; i++)
            for (int j = 0; j < n_axes; j++) {
                double d = x[i * n_axes + j] - first[j];
                var[j] = i == p ? d * d : var[j] + d * d;
            }
        double own = var[0] / (double)(q - p);
        for (int j = 1; j < n_axes; j++)
            own += var[j] / (double)(q - p);
        double own2 = bound2 * own / total;
        own2 = own2 < bound2 ? own2 : bound2;
        long lo = -1, hi = -1;
        for (long i = p; i < q; i++)
            if (dist2(means + i * n_axes, ref, n_axes) <= own2) {
                if (lo < 0)
                    lo = i;
                hi = i;
            }
        if (lo < 0)
            continue;
        /* what the trim cuts off is split again, remembering the level it was cut from */
        if (lo > p) {
            todo[top].a = p;
            todo[top].b = lo;
            todo[top].side = -1;
            memcpy(todo[top].parent, ref, (size_t)n_axes * sizeof *ref);
            top++;
        }
        if (q > hi + 1) {
            todo[top].a = hi + 1;
            todo[top].b = q;
            todo[top].side = 1;
            memcpy(todo[top].parent, ref, (size_t)n_axes * sizeof *ref);
            top++;
        }
        p = lo;
        q = hi + 1;
        long third = (q - p) / 3;
        if (third == 0) { /* too short to tell: kept as a piece of the run, not as a trimmed end */
            if (it.side != 0)
                continue;
        } else {
            long beyond = q - p - third - lean;
            double tilt = tilt_rate * (double)(beyond > 0 ? beyond : 0);
            /* a whole run, motion on both sides (a stance between two swings), may drift as a
             * level leak does */
            double leak =
                it.side == 0 && it.a == 0 && it.b == n ? leak_rate * (double)(q - p - third) : 0.0;
            double allowed = sqrt(bound2 * own / total) + (leak > tilt ? leak : tilt);
            mean_rows(means, n_axes, p, p + third, first);
            mean_rows(means, n_axes, q - third, q, last);
            if (it.side != 0) {
                const double *near_third = it.side > 0 ? first : last,
                             *far_third = it.side > 0 ? last : first;
                double away = sqrt(dist2(far_third, it.parent, n_axes)) -
                              sqrt(dist2(near_third, it.parent, n_axes));
                if (third < w || away > allowed)
                    continue;
            } else if (dist2(first, last, n_axes) > allowed * allowed) {
                continue;
            }
        }
        pstart[count] = p;
        pstop[count] = q;
        memcpy(pref + count * n_axes, ref, (size_t)n_axes * sizeof *ref);
        pown[count] = own;
        count++;
    }
    free(todo);
    return count;
}

/* ------------------------------------------------------------------------- */
/* Plain path in bounded memory: acn_plain_cov + acn_plain_data split into      */
/* chunks, every number computed by the same operations in the same order, so  */
/* the chunked output equals the whole-array one. Store row of sample k:        */
/*   0 a  1 eps        filter posterior (after acn_chunk_bwd: smoothed)          */
/*   2..5 C[k]         (a, eps) smoother gain c00 c01 c10 c11 (0 at the last)    */
/*   6..8 aa ae ee     filter posterior covariance (after acn_chunk_bwd: smoothed) */
/*   9..11 aa ae ee    prior covariance of sample k + 1                          */

/*
 * Forward pass over samples k0 .. k0 + n - 1 (last: the chunk ends the run).
 * carry[0..3] is the prior mean of the chunk's first sample, carry[4..13] its
 * prior covariance (packed): (x0, P0) for k0 = 0; on return, those of the
 * sample after the chunk. Writes the store rows, the filter means xf (n x 4)
 * and standard deviations sdf (n x 4); Pf0 gets the packed posterior of sample
 * 0 (when k0 = 0), Pfn that of the run's last sample (when last).
 * Returns 0, or -(k + 1) if the (a, eps) prior is singular after sample k.
 */
int acn_chunk_fwd(const acn_axis *m, long k0, long n, int last, const double *z,
                  const unsigned char *valid, double *carry, double *store, double *xf, double *sdf,
                  double *Pf0, double *Pfn)
{
    const double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi, b = m->b_eps;
    double F[4][4], P[4][4], dummy[4] = {0.0, 0.0, 0.0, 0.0}, Kk[4], S;
    double r = carry[0], u = carry[1], a = carry[2], ep = carry[3], e;
    transition(m, F);
    unpack(carry + 4, P);
    for (long k = 0; k < n; k++) {
        double *row = store + ACN_ROW * k;
        /* the covariance filter, as acn_plain_cov: K[k] = 0 where sample k is skipped */
        if (valid == NULL || valid[k]) {
            update(dummy, P, H_ACC, 0.0, m->R, &S, Kk);
            /* y = z - (a + eps), x = x + K y, in acn_plain_data's order */
            double y = z[k] - a - ep;
            r += Kk[0] * y;
            u += Kk[1] * y;
            double ka = Kk[2], ke = Kk[3], zk = z[k];
            double an = (a - ka * a) + ka * (zk - ep);
            e = (ep - ke * ep) + ke * (zk - a);
            a = an;
        } else {
            e = ep;
        }
        double *o = xf + 4 * k, *sd = sdf + 4 * k;
        o[0] = r, o[1] = u, o[2] = a, o[3] = e;
        for (int i = 0; i < 4; i++)
            sd[i] = sqrt(P[i][i]);
        if (k0 + k == 0)
            pack(P, Pf0);
        row[0] = a, row[1] = e;
        row[6] = P[2][2], row[7] = P[2][3], row[8] = P[3][3];
        if (last && k == n - 1) {
            pack(P, Pfn);
            for (int i = 2; i < 6; i++)
                row[i] = 0.0;
            row[9] = row[10] = row[11] = 0.0;
            break;
        }
        /* x = F x + b, P = F P F' + Q: the prior of sample k + 1 */
        double paa = P[2][2], pae = P[2][3], pee = P[3][3];
        predict_cov(m, F, P);
        r = r + f01 * u + f02 * a;
        u = u + f12 * a;
        ep = phi * e + b;
        /* C = Pf Fs' inv(Pp), as in acn_plain_cov */
        double qaa = P[2][2], qae = P[2][3], qee = P[3][3];
        double sa = sqrt(qaa), se = sqrt(qee);
        double rho = qae / (sa * se);
        double det = (1.0 - rho * rho) * qaa * qee;
        if (!(det > 0.0)) {
            long at = k0 + k + 1;
            return -(int)(at > 1000000000L ? 1000000000L : at);
        }
        double m00 = paa, m01 = phi * pae, m10 = pae, m11 = phi * pee; /* Pf Fs' */
        row[2] = (m00 * qee - m01 * qae) / det, row[3] = (m01 * qaa - m00 * qae) / det;
        row[4] = (m10 * qee - m11 * qae) / det, row[5] = (m11 * qaa - m10 * qae) / det;
        row[9] = qaa, row[10] = qae, row[11] = qee;
    }
    carry[0] = r, carry[1] = u, carry[2] = a, carry[3] = ep;
    pack(P, carry + 4);
    return 0;
}

/* The r, u rows of a symmetric P as a vector: rr ru ra re uu ua ue. */
enum { RU_N = 7 };
static const int RU_I[RU_N] = {0, 0, 0, 0, 1, 1, 1}, RU_J[RU_N] = {0, 1, 2, 3, 1, 2, 3};

/*
 * One step of the forward covariance from the prior of sample k to that of
 * k + 1 where both read steady row sr, in long double: steady_update with the
 * row's gain, then predict_ru, the (a, eps) block from the row. steady_jump
 * raises this map to a power: an error of one ulp of double in it would grow
 * s-fold, a long double one stays below the per-sample steps' own rounding.
 */
static void steady_step(const acn_axis *m, const double *sr, long double P[4][4])
{
    const long double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi;
    long double PHt[4], G[2][4];
    P[2][2] = sr[8], P[2][3] = P[3][2] = sr[9], P[3][3] = sr[10];
    long double S = P[2][2] + 2.0L * P[2][3] + P[3][3] + (long double)m->R;
    for (int i = 0; i < 4; i++)
        PHt[i] = P[i][2] + P[i][3];
    for (int i = 0; i < 2; i++)
        for (int j = i; j < 4; j++) {
            long double ki = sr[i], kj = sr[j];
            P[i][j] -= ki * PHt[j] + PHt[i] * kj - ki * kj * S;
            P[j][i] = P[i][j];
        }
    P[2][2] = sr[11], P[2][3] = P[3][2] = sr[12], P[3][3] = sr[13];
    for (int j = 0; j < 4; j++) { /* rows 0, 1 of F P, then of F P F' + Q */
        G[0][j] = P[0][j] + f01 * P[1][j] + f02 * P[2][j];
        G[1][j] = P[1][j] + f12 * P[2][j];
    }
    for (int i = 0; i < 2; i++) {
        long double row[4] = {G[i][0] + f01 * G[i][1] + f02 * G[i][2], G[i][1] + f12 * G[i][2],
                              G[i][2], phi * G[i][3]};
        for (int j = i; j < 4; j++)
            P[i][j] = P[j][i] = row[j] + (long double)m->q[PK[i][j]];
    }
    P[2][2] = sr[8], P[2][3] = P[3][2] = sr[9], P[3][3] = sr[10];
}

/*
 * s steady steps at once. Once the rows are steady the step is affine in the
 * r, u rows v: v' = A v + c, the same A and c every sample. Its matrix T =
 * [[A, c], [0, 1]] is read off steady_step at 0 and at the unit vectors, and T^s
 * (v, 1) is taken by squaring: log2(s) 8x8 products, not s steps. In exact
 * arithmetic the same numbers; in doubles they agree with s steps to about
 * 1e-14 relative (tests/estimate/test_chunked.py measures it against them).
 */
static void steady_jump(const acn_axis *m, const double *sr, long s, double P[4][4])
{
    long double T[RU_N + 1][RU_N + 1], y[RU_N + 1], Q[4][4];
    for (int j = 0; j <= RU_N; j++) { /* column j: the step of e_j (j < RU_N) or of 0 (j = RU_N) */
        memset(Q, 0, sizeof Q);
        if (j < RU_N)
            Q[RU_I[j]][RU_J[j]] = Q[RU_J[j]][RU_I[j]] = 1.0;
        steady_step(m, sr, Q);
        for (int i = 0; i < RU_N; i++)
            T[i][j] = Q[RU_I[i]][RU_J[i]];
        T[RU_N][j] = j == RU_N ? 1.0L : 0.0L;
    }
    for (int j = 0; j < RU_N; j++)
        for (int i = 0; i < RU_N; i++)
            T[i][j] -= T[i][RU_N];
    for (int i = 0; i < RU_N; i++)
        y[i] = P[RU_I[i]][RU_J[i]];
    y[RU_N] = 1.0L;
    while (s > 0) { /* y = T^s y: the powers of T commute, so their order does not matter */
        long double U[RU_N + 1][RU_N + 1];
        if (s & 1) {
            long double z[RU_N + 1];
            for (int i = 0; i <= RU_N; i++) {
                z[i] = 0.0L;
                for (int j = 0; j <= RU_N; j++)
                    z[i] += T[i][j] * y[j];
            }
            memcpy(y, z, sizeof y);
        }
        s >>= 1;
        if (s == 0)
            break;
        for (int i = 0; i <= RU_N; i++)
            for (int j = 0; j <= RU_N; j++) {
                U[i][j] = 0.0L;
                for (int l = 0; l <= RU_N; l++)
                    U[i][j] += T[i][l] * T[l][j];
            }
        memcpy(T, U, sizeof T);
    }
    for (int i = 0; i < RU_N; i++)
        P[RU_I[i]][RU_J[i]] = P[RU_J[i]][RU_I[i]] = (double)y[i];
    P[2][2] = sr[8], P[2][3] = P[3][2] = sr[9], P[3][3] = sr[10];
}

/*
 * sqrt(x), taken again only when x's bits differ from the last x's (bits, root: the last x's and
 * its root). The smoothed (a, eps) variances (acn_chunk_cov_lean) stay the same double away from
 * the run's ends, and their roots were half the square roots of the r, u pass (acn_chunk_ru_lean:
 * 20 -> 16-18 ns a sample, measured). The same bits in, the same root out.
 */
static inline double sqrt_again(double x, unsigned long long *bits, double *root)
{
    unsigned long long b = 0; /* at least 64 bits (C99): a double's fit */
    memcpy(&b, &x, sizeof x);
    if (b != *bits) {
        *bits = b;
        *root = sqrt(x);
    }
    return *root;
}

/*
 * The filter's mean update of one sample on the gains k = (K_r, K_u, K_a, K_eps): y = z - (a +
 * eps), x = x + K y, in acn_plain_data's order. x: r, u, a, eps of the prior in; r, u, a of the
 * posterior out. Returns the posterior's eps.
 */
static inline double mean_update(const double k[4], double zk, double x[4])
{
    double y = zk - x[2] - x[3];
    x[0] += k[0] * y;
    x[1] += k[1] * y;
    double an = (x[2] - k[2] * x[2]) + k[2] * (zk - x[3]);
    double e = (x[3] - k[3] * x[3]) + k[3] * (zk - x[2]);
    x[2] = an;
    return e;
}

/* x = F x + b from the posterior (r, u, a in x, eps in e); f: f01, f02, f12, phi, b_eps */
static inline void mean_predict(const double f[5], double e, double x[4])
{
    x[0] = x[0] + f[0] * x[1] + f[1] * x[2];
    x[1] = x[1] + f[2] * x[2];
    x[3] = f[3] * e + f[4];
}

/*
 * The filter's state of one sample after another on the steady row sr, written as the loop of
 * acn_chunk_fwd_steady writes it (states: x32/sd32 compact, else xf/sdf, 4 a sample), for samples
 * k .. stop - 1 with k > 0 and stop below the chunk's last sample. Every operation is the loop's
 * (steady_update, the mean update, predict_ru) on the same numbers in the same order, so the same
 * doubles; what differs is where they live: the r, u rows of P in locals, and the terms that read
 * the steady row alone (S, K_i K_j S, K_i (P H')_j for j in a, eps, the a, eps sds) taken once, not
 * per sample (a filter's run was 38 ns a sample through P in memory). st: r, u, a, eps (the next
 * sample's prior means) in and out.
 */
static void fwd_on_steady(const acn_axis *m, const double *sr, long k, long stop, const double *z,
                          double P[4][4], double st[4], double *store, double *xf, double *sdf,
                          float *x32, float *sd32)
{
    const double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi;
    const double fm[5] = {f01, f02, f12, phi, m->b_eps}, kg[4] = {sr[0], sr[1], sr[2], sr[3]};
    const double q0 = m->q[0], q1 = m->q[1], q2 = m->q[2], q3 = m->q[3];
    const double q4 = m->q[4], q5 = m->q[5], q6 = m->q[6];
    const double k0 = sr[0], k1 = sr[1], ka = sr[2], ke = sr[3];
    /* steady_update's (a, eps) prior is the row's: S, (P H')_a and (P H')_eps are constants */
    const double S = sr[8] + 2.0 * sr[9] + sr[10] + m->R;
    const double ph2 = sr[8] + sr[9], ph3 = sr[9] + sr[10];
    const double c00 = k0 * k0 * S, c01 = k0 * k1 * S, c02 = k0 * ka * S, c03 = k0 * ke * S;
    const double c11 = k1 * k1 * S, c12 = k1 * ka * S, c13 = k1 * ke * S;
    const double k0p2 = k0 * ph2, k0p3 = k0 * ph3, k1p2 = k1 * ph2, k1p3 = k1 * ph3;
    /* the posterior's (a, eps) block, after steady_update */
    const double paa = sr[11], pae = sr[12], sda = sqrt(sr[11]), sde = sqrt(sr[13]);
    double p00 = P[0][0], p01 = P[0][1], p02 = P[0][2], p03 = P[0][3];
    double p11 = P[1][1], p12 = P[1][2], p13 = P[1][3];
    double x[4] = {st[0], st[1], st[2], st[3]};
    for (; k < stop; k++) {
        /* steady_update: P_ij -= K_i (P H')_j + (P H')_i K_j - K_i K_j S */
        double ph0 = p02 + p03, ph1 = p12 + p13;
        p00 -= k0 * ph0 + ph0 * k0 - c00;
        p01 -= k0 * ph1 + ph0 * k1 - c01;
        p02 -= k0p2 + ph0 * ka - c02;
        p03 -= k0p3 + ph0 * ke - c03;
        p11 -= k1 * ph1 + ph1 * k1 - c11;
        p12 -= k1p2 + ph1 * ka - c12;
        p13 -= k1p3 + ph1 * ke - c13;
        double e = mean_update(kg, z[k], x);
        if (x32 != NULL) {
            x32[2 * k] = (float)x[0], x32[2 * k + 1] = (float)x[1];
            sd32[2 * k] = (float)sqrt(p00), sd32[2 * k + 1] = (float)sqrt(p11);
        } else {
            double *o = xf + 4 * k, *sd = sdf + 4 * k;
            o[0] = x[0], o[1] = x[1], o[2] = x[2], o[3] = e;
            sd[0] = sqrt(p00), sd[1] = sqrt(p11), sd[2] = sda, sd[3] = sde;
        }
        double *row = store + ACN_LROW * k;
        row[0] = x[2], row[1] = e;
        /* predict_ru: rows 0, 1 of G = F P, then of G F' + Q (P's a, eps block the posterior's) */
        double g00 = p00 + f01 * p01 + f02 * p02, g01 = p01 + f01 * p11 + f02 * p12;
        double g02 = p02 + f01 * p12 + f02 * paa, g03 = p03 + f01 * p13 + f02 * pae;
        double g11 = p11 + f12 * p12, g12 = p12 + f12 * paa, g13 = p13 + f12 * pae;
        p00 = (g00 + f01 * g01 + f02 * g02) + q0;
        p01 = (g01 + f12 * g02) + q1;
        p02 = g02 + q2;
        p03 = phi * g03 + q3;
        p11 = (g11 + f12 * g12) + q4;
        p12 = g12 + q5;
        p13 = phi * g13 + q6;
        mean_predict(fm, e, x);
    }
    P[0][0] = p00, P[0][1] = P[1][0] = p01, P[0][2] = P[2][0] = p02, P[0][3] = P[3][0] = p03;
    P[1][1] = p11, P[1][2] = P[2][1] = p12, P[1][3] = P[3][1] = p13;
    /* the next prior's (a, eps) block, as the loop sets it */
    P[2][2] = sr[8], P[2][3] = P[3][2] = sr[9], P[3][3] = sr[10];
    memcpy(st, x, sizeof x);
}

/*
 * The filter's means alone on the steady row sr for samples k .. stop - 1, as
 * acn_chunk_fwd_steady's loop takes them where the filter's states are not wanted (their covariance
 * steps are counted by the caller and jumped): the same operations in the same order, without the
 * loop's per-sample tests (11.3 -> 5.8 ns a sample, measured). st: r, u, a, eps in and out, as
 * fwd_on_steady.
 */
static void means_on_steady(const acn_axis *m, const double *sr, long k, long stop, const double *z,
                            double st[4], double *store)
{
    const double fm[5] = {m->f01, m->f02, m->f12, m->phi, m->b_eps};
    const double kg[4] = {sr[0], sr[1], sr[2], sr[3]};
    double x[4] = {st[0], st[1], st[2], st[3]};
    for (; k < stop; k++) {
        double e = mean_update(kg, z[k], x);
        double *row = store + ACN_LROW * k;
        row[0] = x[2], row[1] = e;
        mean_predict(fm, e, x);
    }
    memcpy(st, x, sizeof x);
}

/*
 * acn_chunk_fwd for a chunk of valid samples that follows only valid ones, from
 * the rows of acn_plain_rows (nt of them, the last steady): the gains, smoother
 * gains and (a, eps) blocks are read, the r, u rows of P propagated as in
 * acn_plain_cov_steady. Same arguments and outputs, but a lean store of
 * ACN_LROW doubles per sample: the filter's a, eps, which acn_chunk_bwd_lean
 * turns into the smoothed ones. Everything else the backward passes need is
 * data-independent: they read it from the rows.
 * sdf NULL: the filter's states are not wanted (the smoother alone), so xf gets
 * only its first and last rows, and on steady rows the covariance is not
 * stepped per sample but jumped (steady_jump) to where it is needed: the run's
 * first and last samples and the carry.
 */
int acn_chunk_fwd_steady(const acn_axis *m, long k0, long n, int last, const double *z,
                         const double *srows, long nt, double *carry, double *store, double *xf,
                         double *sdf, double *Pf0, double *Pfn, float *x32, float *sd32)
{
    const double f01 = m->f01, f02 = m->f02, f12 = m->f12, phi = m->phi, b = m->b_eps;
    const double *steady = srows + ACN_SROW * (nt - 1);
    double P[4][4];
    double r = carry[0], u = carry[1], a = carry[2], ep = carry[3], e;
    long pending = 0; /* steady covariance steps not yet taken */
    unpack(carry + 4, P);
    for (long k = 0; k < n; k++) {
        /* the steady row from here to the chunk's end: its own loop (means alone, their covariance
         * steps counted, when the filter's states are not wanted) */
        if (k > 0 && k < n - 1 && k0 + k >= nt - 1) {
            double st[4] = {r, u, a, ep};
            if (sdf != NULL) {
                fwd_on_steady(m, steady, k, n - 1, z, P, st, store, xf, sdf, x32, sd32);
            } else {
                means_on_steady(m, steady, k, n - 1, z, st, store);
                pending += n - 1 - k;
            }
            r = st[0], u = st[1], a = st[2], ep = st[3];
            k = n - 1;
        }
        long g = k0 + k;
        const double *sr = srows + ACN_SROW * (g < nt ? g : nt - 1);
        double *row = store + ACN_LROW * k;
        int end = last && k == n - 1;
        /* skip: the covariance step of this sample is counted, taken later by steady_jump */
        int skip = sdf == NULL && g >= nt - 1 && g > 0 && !end;
        if (!skip) {
            if (pending > 0) {
                steady_jump(m, steady, pending, P);
                pending = 0;
            }
            /* the prior's (a, eps) block is the stored one (as acn_plain_cov_steady) */
            P[2][2] = sr[8], P[2][3] = P[3][2] = sr[9], P[3][3] = sr[10];
            steady_update(P, sr, m->R);
        }
        /* y = z - (a + eps), x = x + K y, in acn_plain_data's order */
        double y = z[k] - a - ep;
        r += sr[0] * y;
        u += sr[1] * y;
        double ka = sr[2], ke = sr[3], zk = z[k];
        double an = (a - ka * a) + ka * (zk - ep);
        e = (ep - ke * ep) + ke * (zk - a);
        a = an;
        if (x32 != NULL) { /* compact: r, u and their sds as float; xf, sdf the chunk's ends */
            x32[2 * k] = (float)r, x32[2 * k + 1] = (float)u;
            sd32[2 * k] = (float)sqrt(P[0][0]), sd32[2 * k + 1] = (float)sqrt(P[1][1]);
            for (int at = 0; at < 2; at++) /* row 0: the first sample's, row 1: the last's */
                if (k == (at ? n - 1 : 0)) {
                    double *o = xf + 4 * at, *sd = sdf + 4 * at;
                    o[0] = r, o[1] = u, o[2] = a, o[3] = e;
                    for (int i = 0; i < 4; i++)
                        sd[i] = sqrt(P[i][i]);
                }
        } else {
            if (sdf != NULL || k == 0 || k == n - 1) {
                double *o = xf + 4 * k;
                o[0] = r, o[1] = u, o[2] = a, o[3] = e;
            }
            if (sdf != NULL)
                for (int i = 0; i < 4; i++)
                    sdf[4 * k + i] = sqrt(P[i][i]);
        }
        if (g == 0)
            pack(P, Pf0);
        row[0] = a, row[1] = e;
        if (end) {
            pack(P, Pfn);
            break;
        }
        if (skip) {
            pending++;
        } else {
            predict_ru(m, P);
            const double *sn =
                srows + ACN_SROW * (g + 1 < nt ? g + 1 : nt - 1); /* the next prior's (a, eps) */
            P[2][2] = sn[8], P[2][3] = P[3][2] = sn[9], P[3][3] = sn[10];
        }
        r = r + f01 * u + f02 * a;
        u = u + f12 * a;
        ep = phi * e + b;
    }
    if (pending > 0)
        steady_jump(m, steady, pending, P);
    carry[0] = r, carry[1] = u, carry[2] = a, carry[3] = ep;
    pack(P, carry + 4);
    return 0;
}

/*
 * One backward step of the smoothed (a, eps) means and covariance: C the
 * smoother gain (c00, c01, c10, c11), x the filter's (a, eps) posterior, pf
 * its covariance (aa, ae, ee) and pn the next prior's. Updates the smoothed
 * values in place; the full and the lean chunk stores lay these out apart.
 */
static inline void bwd_ae_mean(double phi, double b, const double *c, const double *x, double *as,
                               double *es)
{
    double c00 = c[0], c01 = c[1], c10 = c[2], c11 = c[3];
    /* s[k] = s_post[k] + C[k] (s[k+1] - Fs s_post[k] - b), acn_plain_data's order */
    double fa = x[0], fe = phi * x[1] + b;
    double ca = x[0] - (c00 * fa + c01 * fe), ce = x[1] - (c10 * fa + c11 * fe);
    double an = c00 * *as + c01 * *es + ca;
    *es = c10 * *as + c11 * *es + ce;
    *as = an;
}

/* The covariance half of bwd_ae_step: the lean path runs it apart from the means (it needs no
 * data). */
static inline void bwd_ae_cov(const double *c, const double *pf, const double *pn, double *saa,
                              double *sae, double *see)
{
    double c00 = c[0], c01 = c[1], c10 = c[2], c11 = c[3];
    /* Ps = Pf + C (Ps[k+1] - Pp) C' */
    double daa = *saa - pn[0], dae = *sae - pn[1], dee = *see - pn[2];
    double t00 = c00 * daa + c01 * dae, t01 = c00 * dae + c01 * dee;
    double t10 = c10 * daa + c11 * dae, t11 = c10 * dae + c11 * dee;
    *saa = pf[0] + t00 * c00 + t01 * c01;
    *sae = pf[1] + t00 * c10 + t01 * c11;
    *see = pf[2] + t10 * c10 + t11 * c11;
}

static inline void bwd_ae_step(double phi, double b, const double *c, const double *x,
                               const double *pf, const double *pn, double *as, double *es,
                               double *saa, double *sae, double *see)
{
    bwd_ae_mean(phi, b, c, x, as, es);
    bwd_ae_cov(c, pf, pn, saa, sae, see);
}

/*
 * One backward step of the smoothed (a, eps) covariance from rows sr (sample k's)
 * and sn (k + 1's), as bwd_ae_cov; returns 1 when the step left the three doubles
 * as they were and both rows are the steady one (steady != 0). The step is then a
 * function of nothing but those same doubles, so every further step on steady
 * rows gives them again, bit for bit: the callers skip those steps (most of a
 * long run's samples) and keep the values.
 */
static inline int cov_fixed_step(const double *sr, const double *sn, int steady, double *saa,
                                 double *sae, double *see)
{
    double v[3] = {*saa, *sae, *see}, w[3];
    bwd_ae_cov(sr + 4, sr + 11, sn + 8, saa, sae, see);
    w[0] = *saa, w[1] = *sae, w[2] = *see;
    return steady && memcmp(v, w, sizeof v) == 0;
}

/*
 * acn_chunk_bwd over a lean store (acn_chunk_fwd_steady's) of samples k0 ..
 * k0 + n - 1: the smoother gain, the filter's (a, eps) covariance and the next
 * prior's from the rows (row min(k, nt - 1)), the same operations in the same
 * order as acn_chunk_bwd. Writes the smoothed a, eps into the store row; carry
 * as in acn_chunk_bwd. The smoothed (a, eps) covariance is not stored: it needs
 * no data, and acn_chunk_cov_lean gives the same numbers for the r, u pass (the
 * store is 2 doubles a sample, not 5: its fresh pages were most of a run's
 * system time).
 */
void acn_chunk_bwd_lean(const acn_axis *m, long k0, long n, int last, const double *srows, long nt,
                        double *store, double *carry)
{
    const double phi = m->phi, b = m->b_eps;
    double as = carry[0], es = carry[1], saa = carry[2], sae = carry[3], see = carry[4];
    int fixed = 0; /* the covariance is at its fixed point on steady rows (cov_fixed_step) */
    long k = n - 1;
    if (last) { /* the run's last sample is the filter's */
        const double *row = store + ACN_LROW * k;
        const double *sr = srows + ACN_SROW * (k0 + k < nt ? k0 + k : nt - 1);
        as = row[0], es = row[1], saa = sr[11], sae = sr[12], see = sr[13];
        k--;
    }
    for (; k >= 0; k--) {
        double *row = store + ACN_LROW * k;
        long g = k0 + k;
        const double *sr = srows + ACN_SROW * (g < nt ? g : nt - 1);
        const double *sn = srows + ACN_SROW * (g + 1 < nt ? g + 1 : nt - 1);
        bwd_ae_mean(phi, b, sr + 4, row, &as, &es);
        if (!fixed || g < nt - 1)
            fixed = cov_fixed_step(sr, sn, g >= nt - 1, &saa, &sae, &see);
        row[0] = as, row[1] = es;
    }
    carry[0] = as, carry[1] = es, carry[2] = saa, carry[3] = sae, carry[4] = see;
}

/*
 * The smoothed (a, eps) covariance (P_aa, P_ae, P_ee) of samples k0 .. k0 + n - 1
 * into cov (3 doubles a sample), as acn_chunk_bwd_lean steps it: from the run's
 * last row (last) or from after, that of sample k0 + n (the carry that chunk's
 * backward pass started from). The same operations on the same numbers: the
 * same doubles.
 */
void acn_chunk_cov_lean(const acn_axis *m, long k0, long n, int last, const double *srows, long nt,
                        const double *after, double *cov)
{
    (void)m;
    double saa, sae, see;
    long k = n - 1;
    if (last) {
        const double *sr = srows + ACN_SROW * (k0 + k < nt ? k0 + k : nt - 1);
        saa = sr[11], sae = sr[12], see = sr[13];
        cov[3 * k] = saa, cov[3 * k + 1] = sae, cov[3 * k + 2] = see;
        k--;
    } else {
        saa = after[0], sae = after[1], see = after[2];
    }
    for (; k >= 0; k--) {
        long g = k0 + k;
        const double *sr = srows + ACN_SROW * (g < nt ? g : nt - 1);
        const double *sn = srows + ACN_SROW * (g + 1 < nt ? g + 1 : nt - 1);
        int fixed = cov_fixed_step(sr, sn, g >= nt - 1, &saa, &sae, &see);
        cov[3 * k] = saa, cov[3 * k + 1] = sae, cov[3 * k + 2] = see;
        /* at the fixed point, every sample down to row nt - 1 gets these same doubles */
        for (long stop = nt - 1 - k0; fixed && k - 1 >= stop && k - 1 >= 0; k--)
            cov[3 * (k - 1)] = saa, cov[3 * (k - 1) + 1] = sae, cov[3 * (k - 1) + 2] = see;
    }
}

/*
 * Backward pass over the n store rows of one chunk, last to first (last: the
 * chunk ends the run, whose last sample is the filter's). carry holds the
 * smoothed a, eps, P_aa, P_ae, P_ee of the sample after the chunk; on return,
 * those of the chunk's first sample. Rows get the smoothed values in place.
 */
void acn_chunk_bwd(const acn_axis *m, long n, int last, double *store, double *carry)
{
    const double phi = m->phi, b = m->b_eps;
    double as = carry[0], es = carry[1], saa = carry[2], sae = carry[3], see = carry[4];
    long k = n - 1;
    if (last) {
        const double *row = store + ACN_ROW * k;
        as = row[0], es = row[1], saa = row[6], sae = row[7], see = row[8];
        k--;
    }
    for (; k >= 0; k--) {
        double *row = store + ACN_ROW * k;
        bwd_ae_step(phi, b, row + 2, row, row + 6, row + 9, &as, &es, &saa, &sae, &see);
        row[0] = as, row[1] = es, row[6] = saa, row[7] = sae, row[8] = see;
    }
    carry[0] = as, carry[1] = es, carry[2] = saa, carry[3] = sae, carry[4] = see;
}

/*
 * One step of the smoothed r, u recursion of acn_plain_cov, term by term:
 * v = (r, u, P_rr, P_ru, P_ra, P_uu, P_ua, beta_r (2), beta_u (2)) of sample k
 * to sample k + 1, from the smoothed a, P_aa at k, a, P_aa, P_ae at k + 1 and
 * the smoother gain C[k].
 */
static void ru_step(const acn_axis *m, double v[11], double a0, double aa, double a1, double aa1,
                    double ae1, const double *C)
{
    const double gr = m->gr, gu = m->gu, f01 = m->f01, f02 = m->f02, f12 = m->f12;
    const double s[6] = {v[2], v[3], v[4], v[5], v[6], aa};
    double beta[4] = {v[7], v[8], v[9], v[10]}, out[3];
    ru_cov_step(m, s, beta, C, aa1, ae1, out);
    /* u[k+1] = u[k] + f12 a[k] + gu (a[k+1] - a[k]);  r likewise */
    double r = v[0], u = v[1], dw = a1 - a0;
    r = r + (f01 * u + (f02 * a0 + gr * dw));
    u = u + (f12 * a0 + gu * dw);
    v[0] = r, v[1] = u, v[2] = out[0], v[3] = out[2], v[5] = out[1];
    v[4] = beta[0] * aa1 + beta[1] * ae1; /* P_ra */
    v[6] = beta[2] * aa1 + beta[3] * ae1; /* P_ua */
    v[7] = beta[0], v[8] = beta[1], v[9] = beta[2], v[10] = beta[3];
}

/*
 * Forward pass of smoothed r, u over n samples of one chunk: writes xs and the
 * standard deviations sds (n x 4) of each, reading store rows 0 .. n (row n is
 * the next chunk's first; the run's last sample is the caller's, the filter's).
 * carry: r, u, P_rr, P_ru, P_ra, P_uu, P_ua and beta_r (2), beta_u (2) of the
 * chunk's first sample (see acn_plain_cov); on return, of the sample after it.
 */
void acn_chunk_ru(const acn_axis *m, long n, const double *store, double *carry, double *xs,
                  double *sds)
{
    for (long k = 0; k < n; k++) {
        const double *row = store + ACN_ROW * k, *nx = row + ACN_ROW;
        double *o = xs + 4 * k, *sd = sds + 4 * k;
        o[0] = carry[0], o[1] = carry[1], o[2] = row[0], o[3] = row[1];
        sd[0] = sqrt(carry[2]), sd[1] = sqrt(carry[5]), sd[2] = sqrt(row[6]), sd[3] = sqrt(row[8]);
        ru_step(m, carry, row[0], row[6], nx[0], nx[6], nx[7], row + 2);
    }
}

/*
 * acn_chunk_ru over a lean store (after acn_chunk_bwd_lean) of samples k0 ..,
 * C from the rows, the smoothed (a, eps) covariance from cov (acn_chunk_cov_lean:
 * rows 0 .. n, row n the next sample's).
 */
void acn_chunk_ru_lean(const acn_axis *m, long k0, long n, const double *store, const double *cov,
                       const double *srows, long nt, double *carry, double *xs, double *sds,
                       float *x32, float *sd32)
{
    /* the carry and the model in locals: the stores to xs, sds cannot alias them, so the recursion
     * stays in registers (20 ns a sample, 23-24 through memory, measured); the same operations */
    const acn_axis mm = *m;
    double v[11], aa_root = 0.0, ee_root = 0.0;
    unsigned long long aa_bits = ~0ULL, ee_bits = ~0ULL;
    memcpy(v, carry, sizeof v);
    if (x32 !=
        NULL) { /* the compact output: r, u and their sds rounded to float as numpy casts them */
        for (long k = 0; k < n; k++) {
            const double *row = store + ACN_LROW * k, *nx = row + ACN_LROW;
            const double *pc = cov + 3 * k, *pn = pc + 3;
            const double *sr = srows + ACN_SROW * (k0 + k < nt ? k0 + k : nt - 1);
            x32[2 * k] = (float)v[0], x32[2 * k + 1] = (float)v[1];
            sd32[2 * k] = (float)sqrt(v[2]), sd32[2 * k + 1] = (float)sqrt(v[5]);
            ru_step(&mm, v, row[0], pc[0], nx[0], pn[0], pn[1], sr + 4);
        }
        memcpy(carry, v, sizeof v);
        return;
    }
    for (long k = 0; k < n; k++) {
        const double *row = store + ACN_LROW * k, *nx = row + ACN_LROW;
        const double *pc = cov + 3 * k, *pn = pc + 3;
        const double *sr = srows + ACN_SROW * (k0 + k < nt ? k0 + k : nt - 1);
        double *o = xs + 4 * k, *sd = sds + 4 * k;
        o[0] = v[0], o[1] = v[1], o[2] = row[0], o[3] = row[1];
        sd[0] = sqrt(v[2]), sd[1] = sqrt(v[5]);
        sd[2] = sqrt_again(pc[0], &aa_bits, &aa_root);
        sd[3] = sqrt_again(pc[2], &ee_bits, &ee_root);
        ru_step(&mm, v, row[0], pc[0], nx[0], pn[0], pn[1], sr + 4);
    }
    memcpy(carry, v, sizeof v);
}

/* ------------------------------------------------------------------------- */
/* General path in bounded memory: acn_general split into chunks, the same     */
/* steps (general_update, rts_step) in the same order. Store row of sample k:  */
/*   0..3 x_post[k]  4..13 P_post[k]                                            */
/* The backward pass predicts the prior of k + 1 from them again, with the     */
/* forward pass's own predict_mean and predict_packed: the same numbers, and   */
/* half the store (its writes were a third of `smooth --zupt auto` at 1e7).    */

/* Sample k's filter outputs from its posterior (x, p): its store row, and xf, sdf if wanted */
static inline void fwd_put(long k, const double x[4], const double *p, double *store, int width,
                           double *xf, double *sdf)
{
    double *row = store + width * k;
    memcpy(row, x, 4 * sizeof(double));
    if (xf != NULL) {
        memcpy(xf + 4 * k, x, 4 * sizeof(double));
        sdf[4 * k + 0] = sqrt(p[RR]), sdf[4 * k + 1] = sqrt(p[UU]);
        sdf[4 * k + 2] = sqrt(p[AA]), sdf[4 * k + 3] = sqrt(p[EE]);
    }
    if (width == ACN_GROW)
        memcpy(row + 4, p, 10 * sizeof(double));
}

/*
 * Extra ei is a zero-velocity update (h = e_u, which update_aid steps with
 * constant indices) and the only extra of its sample: the common measurement
 * of an aided run (half the samples of a record with rests). The chunk kernels
 * run such samples, applied outright, and those with no extra in a loop of
 * their own with x and p in locals, where the general step's variable indices
 * keep them in memory.
 */
static inline int lone_zupt(long ei, long n_extra, const long *ek, const double *eh)
{
    const double *h = eh + 4 * ei;
    return h[0] == 0.0 && h[1] == 1.0 && h[2] == 0.0 && h[3] == 0.0 &&
           (ei + 1 == n_extra || ek[ei + 1] != ek[ei]);
}

/*
 * chunkg_fwd's steps from sample k while each sample has no extra or a lone
 * zupt without a gate: general_update's operations on the same numbers in the same order
 * (update_aid's e_u case), so the same doubles; in (x, p) locals, which the
 * general step's variable indices keep in memory. Returns the first sample it
 * did not step (n after the run's last sample, whose prior it does not make).
 */
static long fwd_simple(const acn_axis *m, long k, long n, int last, const double *z,
                       const unsigned char *valid, long *eip, long n_extra, const long *ek,
                       const double *eh, const double *ez, const double *eR, const double *egate,
                       unsigned char *applied, double *xio, double *pio, double *store, int width,
                       double *xf, double *sdf, double *xpr, double *ppr, double *ey, double *eS)
{
    double p[10], x[4], S;
    long ei = *eip;
    memcpy(x, xio, sizeof x);
    memcpy(p, pio, sizeof p);
    for (; k < n; k++) {
        int aid = ei < n_extra && ek[ei] == k;
        if (aid && !(lone_zupt(ei, n_extra, ek, eh) && !(egate[ei] > 0.0)))
            break; /* a gated aid, another h or several: general_update's step */
        if (xpr != NULL) {
            memcpy(xpr + 4 * k, x, sizeof x);
            memcpy(ppr + 10 * k, p, sizeof p);
        }
        if (valid == NULL || valid[k])
            update_sparse(x, p, H_ACC, NZ_ACC, 2, z[k], m->R, &S);
        if (aid) {
            double y = update_sparse(x, p, H_UNIT[1], NZ_UNIT[1], 1, ez[ei], eR[ei], &S);
            applied[ei] = 1;
            if (ey != NULL) {
                ey[ei] = y;
                eS[ei] = S;
            }
            ei++;
        }
        fwd_put(k, x, p, store, width, xf, sdf);
        if (last && k == n - 1) {
            k = n;
            break;
        }
        predict_mean(m, x);
        predict_p(m, p);
    }
    memcpy(xio, x, sizeof x);
    memcpy(pio, p, sizeof p);
    *eip = ei;
    return k;
}

/*
 * Forward over samples k0 .. k0 + n - 1, extras as in acn_general with ek
 * counted from the chunk's first sample. carry: the prior mean (4) and packed
 * covariance (10) of the chunk's first sample; on return, of the next sample.
 * Writes the store rows and the filter means xf and standard deviations sdf (n x 4);
 * xpr, ppr (NULL: not written): each sample's prior mean (n x 4) and packed
 * covariance (n x 10), for --covariances (the row holds the posterior only).
 * ey, eS (NULL: not written): each extra's innovation and its variance, as
 * general_update gives them (the aids' NIS of a run over the memory budget).
 * Runs of samples with no extra or a lone zupt go through fwd_simple.
 */
static inline void chunkg_fwd(const acn_axis *m, long n, int last, const double *z,
                              const unsigned char *valid, long n_extra, const long *ek,
                              const double *eh, const double *ez, const double *eR,
                              const double *egate, unsigned char *applied, double *carry,
                              double *store, int width, double *xf, double *sdf, double *xpr,
                              double *ppr, double *ey, double *eS)
{
    double p[10], x[4];
    long ei = 0;
    memcpy(x, carry, sizeof x);
    memcpy(p, carry + 4, sizeof p);
    for (long k = 0; k < n; k++) {
        k = fwd_simple(m, k, n, last, z, valid, &ei, n_extra, ek, eh, ez, eR, egate, applied, x, p,
                       store, width, xf, sdf, xpr, ppr, ey, eS);
        if (k == n)
            break;
        if (xpr != NULL) {
            memcpy(xpr + 4 * k, x, sizeof x);
            memcpy(ppr + 10 * k, p, sizeof p);
        }
        ei = general_update(m, k, valid == NULL || valid[k], z[k], x, p, ei, n_extra, ek, eh, ez,
                            eR, egate, applied, ey, eS);
        fwd_put(k, x, p, store, width, xf, sdf);
        if (last && k == n - 1)
            break;
        predict_mean(m, x);
        predict_p(m, p);
    }
    memcpy(carry, x, sizeof x);
    memcpy(carry + 4, p, sizeof p);
}

void acn_chunkg_fwd(const acn_axis *m, long n, int last, const double *z,
                    const unsigned char *valid, long n_extra, const long *ek, const double *eh,
                    const double *ez, const double *eR, const double *egate, unsigned char *applied,
                    double *carry, double *store, double *xf, double *sdf, double *xpr, double *ppr,
                    double *ey, double *eS)
{
    chunkg_fwd(m, n, last, z, valid, n_extra, ek, eh, ez, eR, egate, applied, carry, store,
               ACN_GROW, xf, sdf, xpr, ppr, ey, eS);
}

/*
 * acn_chunkg_fwd with a lean store: rows of ACN_GLROW doubles, the posterior
 * mean alone. Its covariance needs no data: acn_chunkg_cov makes it again for
 * the backward pass from the chunk's first prior covariance (the 10 doubles a
 * sample written to disk and read back were a third of `smooth --zupt auto`'s
 * time at 1e7 samples). xf, sdf NULL: the filter's states are not wanted.
 */
void acn_chunkg_fwd_lean(const acn_axis *m, long n, int last, const double *z,
                         const unsigned char *valid, long n_extra, const long *ek, const double *eh,
                         const double *ez, const double *eR, const double *egate,
                         unsigned char *applied, double *carry, double *store, double *xf,
                         double *sdf, double *ey, double *eS)
{
    chunkg_fwd(m, n, last, z, valid, n_extra, ek, eh, ez, eR, egate, applied, carry, store,
               ACN_GLROW, xf, sdf, NULL, NULL, ey, eS);
}

/*
 * The filter's posterior covariance (packed, n x 10 into pst) of a chunk's n
 * samples, as acn_chunkg_fwd stepped it: from p0, the prior covariance of the
 * chunk's first sample, the acceleration where valid, then the extras ek[i] ==
 * k that the forward pass applied (applied[i]: a gated one it skipped is
 * skipped). update_sparse's covariance reads neither the mean nor z: the same
 * operations on the same numbers, so the same doubles.
 */
/* acn_chunkg_cov's steps from sample k as fwd_simple's (a lone zupt that was applied) */
static long cov_simple(const acn_axis *m, long k, long n, int last, const unsigned char *valid,
                       long *eip, long n_extra, const long *ek, const double *eh, const double *eR,
                       const unsigned char *applied, double *pio, double *pst)
{
    double p[10], x[4] = {0.0, 0.0, 0.0, 0.0}, S;
    long ei = *eip;
    memcpy(p, pio, sizeof p);
    for (; k < n; k++) {
        int aid = ei < n_extra && ek[ei] == k;
        if (aid && !(applied[ei] && lone_zupt(ei, n_extra, ek, eh)))
            break;
        if (valid == NULL || valid[k])
            update_sparse(x, p, H_ACC, NZ_ACC, 2, 0.0, m->R, &S);
        if (aid)
            update_sparse(x, p, H_UNIT[1], NZ_UNIT[1], 1, 0.0, eR[ei++], &S);
        memcpy(pst + 10 * k, p, sizeof p);
        if (last && k == n - 1) {
            k = n;
            break;
        }
        predict_p(m, p);
    }
    memcpy(pio, p, sizeof p);
    *eip = ei;
    return k;
}

void acn_chunkg_cov(const acn_axis *m, long n, int last, const unsigned char *valid, long n_extra,
                    const long *ek, const double *eh, const double *eR,
                    const unsigned char *applied, const double *p0, double *pst)
{
    double p[10], x[4] = {0.0, 0.0, 0.0, 0.0}, S;
    long ei = 0;
    memcpy(p, p0, sizeof p);
    for (long k = 0; k < n; k++) {
        k = cov_simple(m, k, n, last, valid, &ei, n_extra, ek, eh, eR, applied, p, pst);
        if (k == n)
            break;
        if (valid == NULL || valid[k])
            update_sparse(x, p, H_ACC, NZ_ACC, 2, 0.0, m->R, &S);
        for (; ei < n_extra && ek[ei] == k; ei++) {
            const double *h = eh + 4 * ei;
            int nz[4], nn = 0;
            for (int j = 0; j < 4; j++)
                if (h[j] != 0.0)
                    nz[nn++] = j;
            if (applied[ei])
                update_aid(x, p, h, nz, nn, 0.0, eR[ei], &S);
        }
        memcpy(pst + 10 * k, p, sizeof p);
        if (last && k == n - 1)
            break;
        predict_p(m, p);
    }
}

/*
 * A 64-bit digest of n aids' samples, h and R, in order. Each of an aid's six
 * words goes into a chain of its own, x = (x ^ w) * p (FNV-1a's step on 64-bit
 * words; both operations are one to one, so a chain's end differs whenever one
 * word differs), and the chains run side by side: a few cycles an aid, where
 * zlib's CRC-32 from Python cost 3 % of `smooth --zupt auto`. The chains folded
 * the same way at the end. Meant for accidental differences, not an adversary.
 */
unsigned long long acn_aids_digest(long n, const long *ek, const double *eh, const double *eR)
{
    const unsigned long long basis = 14695981039346656037ULL, prime = 1099511628211ULL;
    unsigned long long c[6] = {basis, basis, basis, basis, basis, basis};
    for (long i = 0; i < n; i++) {
        unsigned long long w[6];
        w[0] = (unsigned long long)ek[i];
        memcpy(w + 1, eh + 4 * i, 4 * sizeof(double));
        memcpy(w + 5, eR + i, sizeof(double));
        for (int j = 0; j < 6; j++)
            c[j] = (c[j] ^ w[j]) * prime;
    }
    unsigned long long d = basis ^ (unsigned long long)n;
    for (int j = 0; j < 6; j++)
        d = (d ^ c[j]) * prime;
    return d;
}

/* What the backward step of sample k takes from row k alone: the prior of k + 1 predicted again and
   the smoother gain (bad: that prior is not positive definite) */
typedef struct {
    double xp[4], pp[10], Ct[4][4];
    int bad;
} bwd_gain;

static inline void bwd_gain_of(const acn_axis *m, const double *xk, const double *pk, bwd_gain *g)
{
    double B[4][4];
    memcpy(g->xp, xk, sizeof g->xp);
    predict_mean(m, g->xp);
    fp_rows(m, pk, B);
    predict_packed(m, B, g->pp);
    g->bad = smoother_gain(g->pp, B, g->Ct) != 0;
}

/*
 * bwd_gain_of for rows k (into g[0]) and k - 1 (g[1]) at once: the two
 * factorisations side by side, so that the one's chain of divisions overlaps
 * the other's (each waits on its own four in turn).
 */
static void bwd_gains2(const acn_axis *m, const double *xst, int xw, const double *pst, int pw,
                       long k, bwd_gain g[2])
{
    double B[2][4][4];
    ldl4 f[2];
    for (int l = 0; l < 2; l++) {
        memcpy(g[l].xp, xst + xw * (k - l), sizeof g[l].xp);
        predict_mean(m, g[l].xp);
        fp_rows(m, pst + pw * (k - l), B[l]);
        predict_packed(m, B[l], g[l].pp);
    }
    for (int l = 0; l < 2; l++)
        ldl_factor(g[l].pp, &f[l]);
    for (int l = 0; l < 2; l++) {
        g[l].bad = !f[l].ok && gain_equilibrated(g[l].pp, B[l], g[l].Ct) != 0;
        if (f[l].ok)
            ldl_solve(&f[l], B[l], g[l].Ct);
    }
}

/* The gains of rows k and k - 1 into g[0], g[1] (of row k alone when it is the chunk's first) */
static inline void bwd_gains(const acn_axis *m, const double *xst, int xw, const double *pst,
                             int pw, long k, bwd_gain g[2])
{
    if (k >= 1)
        bwd_gains2(m, xst, xw, pst, pw, k, g);
    else
        bwd_gain_of(m, xst + xw * k, pst + pw * k, &g[0]);
}

/*
 * Backward over the n store rows of one chunk (last: it ends the run, whose
 * last sample is the filter's). carry: the smoothed mean (4) and packed
 * covariance (10) of the sample after the chunk; on return, of its first.
 * Writes xs and the standard deviations sds (n x 4), and ps (NULL: not written)
 * the packed covariances (n x 10), for --covariances. k0 names samples in the
 * error: returns -(k + 1) if the prior of sample k + 1 is not positive definite.
 * rts_step's operations in another order: the gains depend on the store
 * alone, the update on the sample after's, so the gains are made two samples
 * at a time (bwd_gains2), the next two before these two's updates, and the
 * divisions of the ones overlap the products of the others.
 */
static inline int chunkg_bwd(const acn_axis *m, long k0, long n, int last, const double *xst,
                             int xw, const double *pst, int pw, double *carry, double *xs,
                             double *sds, double *ps)
{
    double x1[4], P1[10];
    bwd_gain g[4]; /* the gains of two samples, then of the two before them */
    memcpy(x1, carry, sizeof x1);
    memcpy(P1, carry + 4, sizeof P1);
    long k = n - 1;
    if (last) {
        memcpy(x1, xst + xw * k, sizeof x1);
        memcpy(P1, pst + pw * k, sizeof P1);
        memcpy(xs + 4 * k, x1, sizeof x1);
        sds[4 * k + 0] = sqrt(P1[RR]), sds[4 * k + 1] = sqrt(P1[UU]);
        sds[4 * k + 2] = sqrt(P1[AA]), sds[4 * k + 3] = sqrt(P1[EE]);
        if (ps != NULL)
            memcpy(ps + 10 * k, P1, sizeof P1);
        k--;
    }
    int cur = 0;
    if (k >= 0)
        bwd_gains(m, xst, xw, pst, pw, k, g);
    for (; k >= 0; k -= 2, cur = 2 - cur) {
        bwd_gain *c = g + cur;
        if (k >= 2)
            bwd_gains(m, xst, xw, pst, pw, k - 2, g + 2 - cur);
        for (int h = 0; h < 2 && k - h >= 0; h++) {
            long j = k - h;
            if (c[h].bad) {
                long at = k0 + j + 1;
                return -(int)(at > 1000000000L ? 1000000000L : at);
            }
            rts_apply(c[h].Ct, xst + xw * j, pst + pw * j, c[h].xp, c[h].pp, x1, P1, x1, P1);
            memcpy(xs + 4 * j, x1, sizeof x1);
            sds[4 * j + 0] = sqrt(P1[RR]), sds[4 * j + 1] = sqrt(P1[UU]);
            sds[4 * j + 2] = sqrt(P1[AA]), sds[4 * j + 3] = sqrt(P1[EE]);
            if (ps != NULL)
                memcpy(ps + 10 * j, P1, sizeof P1);
        }
    }
    memcpy(carry, x1, sizeof x1);
    memcpy(carry + 4, P1, sizeof P1);
    return 0;
}

int acn_chunkg_bwd(const acn_axis *m, long k0, long n, int last, const double *store, double *carry,
                   double *xs, double *sds, double *ps)
{
    return chunkg_bwd(m, k0, n, last, store, ACN_GROW, store + 4, ACN_GROW, carry, xs, sds, ps);
}

/*
 * acn_chunkg_bwd over a lean store: the posterior means from xst (ACN_GLROW a
 * sample), their covariances from pst (10 a sample, acn_chunkg_cov's).
 */
int acn_chunkg_bwd_lean(const acn_axis *m, long k0, long n, int last, const double *xst,
                        const double *pst, double *carry, double *xs, double *sds)
{
    return chunkg_bwd(m, k0, n, last, xst, ACN_GLROW, pst, 10, carry, xs, sds, NULL);
}

/* ---- the rest decision's kinematic filter (rests.py, _Kinematic; fastsmooth.h) ----------------
 */

/* Python's max(x, 0.0): x unless 0.0 is larger (a NaN stays) */
static double kin_pos(double x)
{
    return 0.0 > x ? 0.0 : x;
}

/* one row of the sums on: [V, A, W] (3 n_axes) at sample k to k + 1 in place, row x[k] summed as
   acn_kin_sums sums it (W from the V before) */
static void kin_rec_step(int n_axes, const double *row, double Ts, double *vaw)
{
    for (int j = 0; j < n_axes; j++) {
        double v = vaw[j];
        vaw[j] = v + row[j] * Ts;
        vaw[n_axes + j] = vaw[n_axes + j] + fabs(row[j]) * Ts;
        vaw[2 * n_axes + j] = vaw[2 * n_axes + j] + v * Ts;
    }
}

static const double *kin_rec_x(const acn_kin_rec *r, long k)
{
    return r->x + (r->reverse ? r->n - 1 - k : k) * r->n_axes;
}

/* a record whose rows fit (at most 8 axes: row[96], vaw[24]) and whose length the checkpoints can
 * index */
static int kin_rec_bad(const acn_kin_rec *r)
{
    return r == NULL || r->n < 0 || r->n_axes < 1 || r->n_axes > 8 || r->every < 1 ||
           r->x == NULL || r->n > LONG_MAX / 24;
}

/* a record the kernels can read: sound, and its checkpoints made for the n, every and axes it has
 * now */
static int kin_rec_ready(const acn_kin_rec *r)
{
    return !kin_rec_bad(r) && r->cp != NULL && r->cp_n == r->n && r->cp_every == r->every &&
           r->cp_axes == r->n_axes;
}

/* the events of a pass over n samples, m candidates: in sample order within the record, each kind's
   index within its array (a fix names an axis, a candidate's start or end a candidate) */
static int kin_events_bad(long n, int n_axes, long m, long n_ev, const long *ev_k,
                          const int *ev_kind, const long *ev_i)
{
    if (m < 0 || n_ev < 0) {
        return 1;
    }
    for (long e = 0; e < n_ev; e++) {
        long k = ev_k[e], i = ev_i[e];
        int kind = ev_kind[e];
        if (k < 0 || k > n || (e > 0 && k < ev_k[e - 1]) || kind < 0 || kind > 2 || i < 0 ||
            i >= (kind == 1 ? n_axes : m)) {
            return 1;
        }
    }
    return 0;
}

int acn_kin_checkpoints(acn_kin_rec *r, double *cp)
{
    if (kin_rec_bad(r) || cp == NULL) {
        return -1;
    }
    int w = 3 * r->n_axes;
    double vaw[24] = {0.0};
    /* a checkpoint, then the rows up to the next one: no division per row */
    for (long b = 0, c = 0; b <= r->n; b += r->every, c++) {
        memcpy(cp + c * w, vaw, sizeof(double) * (size_t)w);
        long end = r->n - b < r->every ? r->n : b + r->every;
        for (long k = b; k < end; k++) {
            kin_rec_step(r->n_axes, kin_rec_x(r, k), r->Ts, vaw);
        }
    }
    r->cp = cp;
    for (int i = 0; i < 4; i++) {
        r->at[i] = -1;
        r->used[i] = 0;
    }
    r->clock = 0;
    r->cp_n = r->n, r->cp_every = r->every, r->cp_axes = r->n_axes;
    return 0;
}

/* sample k's row [V, A, W]: a kept row, or one summed on from the nearest checkpoint or kept row
   before k (into the least recently read slot, unless it goes on from a kept one) */
static const double *kin_rec_row(acn_kin_rec *r, long k)
{
    int w = 3 * r->n_axes, from = -1, lru = 0;
    long base = (k / r->every) * r->every;
    for (int i = 0; i < 4; i++) {
        if (r->at[i] == k) {
            r->used[i] = ++r->clock;
            return r->row + 24 * i;
        }
        if (r->at[i] > base && r->at[i] < k && (from < 0 || r->at[i] > r->at[from])) {
            from = i;
            base = r->at[i];
        }
        if (r->used[i] < r->used[lru]) {
            lru = i;
        }
    }
    double *row = r->row + 24 * lru;
    if (from >= 0) {
        if (from != lru) {
            memcpy(row, r->row + 24 * from, sizeof(double) * (size_t)w);
        }
    } else {
        memcpy(row, r->cp + (base / r->every) * w, sizeof(double) * (size_t)w);
    }
    for (long i = base; i < k; i++) {
        kin_rec_step(r->n_axes, kin_rec_x(r, i), r->Ts, row);
    }
    r->at[lru] = k;
    r->used[lru] = ++r->clock;
    return row;
}

int acn_kin_sums_at(acn_kin_rec *r, long k, double *out)
{
    if (!kin_rec_ready(r) || k < 0 || k > r->n) {
        return -1;
    }
    memcpy(out, kin_rec_row(r, k), sizeof(double) * 3 * (size_t)r->n_axes);
    return 0;
}

/*
 * The rest decision's kinematic filter (host/estimate/rests.py, _Kinematic): per
 * axis the state (r, u, e) and its symmetric covariance, 9 doubles
 *   r u e  Prr Pru Pre Puu Pue Pee
 * n_axes of them side by side in s. r: the record's sums V, A, W (acn_kin_rec,
 * below; rests.py says which). The arithmetic is the Python reference's
 * (tests/support/rests_reference.py), in its order.
 *   kin_to    propagate s from sample k0 to k (k > k0)
 *   kin_aid   propagate, then the scalar measurement z of state i (0: r,
 *                 1: u) with variance var on axis `axis`, or on every axis (-1)
 *   kin_side  a side's test of a candidate of `len` samples and the given
 *                 level: v, its sd, r, its sd per axis into out (4 rows of
 *                 n_axes, v times sign); returns sum of v^2 / (sd^2 + sigma2).
 *                 The level's path since the last aid (D ago) is taken as
 *                 linear; the sd is widened by a leak that changed by L along
 *                 any path (leak L D), a mean acceleration error no level
 *                 explains (drift D) and a scale factor's share of what moved
 *                 since (scale x the integral of |x|); r's by that times D
 *   kin_jump  the level's jump beyond 3 sd of the filter's (0: it has none)
 */
static void kin_to(int n_axes, double *s, acn_kin_rec *rec, long k0, long k, double Ts, double q,
                   const double *qv)
{
    long m = k - k0;
    if (m <= 0) {
        return;
    }
    double D = (double)m * Ts;
    double c = Ts * Ts * (double)m * (double)(m - 1) / 2.0;
    double D2 = D * D;
    double D3 = D2 * D;
    /* the level's random walk, integrated once into u and twice into r (signs: u and r get -e), and
       the velocity noise of the integrated sensor noise */
    double qrr = q * D3 * D2 / 20, qru = q * D2 * D2 / 8, qre = -q * D3 / 6;
    double quu = q * D3 / 3, que = -q * D2 / 2, qee = q * D;
    const double *rk = kin_rec_row(rec, k), *r0 = kin_rec_row(rec, k0);
    for (int j = 0; j < n_axes; j++) {
        double *x = s + 9 * j;
        double r = x[0], u = x[1], e = x[2], a = x[3], b = x[4], cc = x[5], d = x[6], f = x[7],
               g = x[8];
        double dV = rk[j] - r0[j];
        double dW = rk[2 * n_axes + j] - r0[2 * n_axes + j] - D * r0[j];
        /* F P F' with F = [[1, D, -c], [0, 1, -D], [0, 0, 1]]: the rows of F P first */
        double x0 = a + D * b - c * cc, x1 = b + D * d - c * f, x2 = cc + D * f - c * g;
        double y1 = d - D * f, y2 = f - D * g;
        x[0] = r + D * u + dW - c * e;
        x[1] = u + dV - D * e;
        x[3] = x0 + D * x1 - c * x2 + qrr + qv[j] * D3 / 3;
        x[4] = x1 - D * x2 + qru + qv[j] * D2 / 2;
        x[5] = x2 + qre;
        x[6] = y1 - D * y2 + quu + qv[j] * D;
        x[7] = y2 + que;
        x[8] = g + qee;
    }
}

/* in place on one axis' 9 doubles: the scalar measurement z = state i + v, v ~ N(0, var) */
static void kin_update(double *x, int i, double z, double var)
{
    double r = x[0], u = x[1], e = x[2], a = x[3], b = x[4], c = x[5], d = x[6], f = x[7], g = x[8];
    double P0 = i == 0 ? a : i == 1 ? b : c;
    double P1 = i == 0 ? b : i == 1 ? d : f;
    double P2 = i == 0 ? c : i == 1 ? f : g;
    double S = (i == 0 ? P0 : i == 1 ? P1 : P2) + var;
    double K0 = P0 / S, K1 = P1 / S, K2 = P2 / S;
    double innov = z - x[i];
    x[0] = r + K0 * innov;
    x[1] = u + K1 * innov;
    x[2] = e + K2 * innov;
    x[3] = a - K0 * P0;
    x[4] = b - K0 * P1;
    x[5] = c - K0 * P2;
    x[6] = d - K1 * P1;
    x[7] = f - K1 * P2;
    x[8] = g - K2 * P2;
}

static void kin_aid(int n_axes, double *s, acn_kin_rec *r, long k0, long k, double Ts, double q,
                    const double *qv, int axis, int i, double z, double var)
{
    kin_to(n_axes, s, r, k0, k, Ts, q, qv);
    for (int j = 0; j < n_axes; j++) {
        if (axis < 0 || axis == j) {
            kin_update(s + 9 * j, i, z, var);
        }
    }
}

static double kin_side(int n_axes, const double *s, acn_kin_rec *r, long k, long aid_k, double Ts,
                       const double *level, const double *R, long len, double leak, double drift,
                       double scale, double sigma2, double sign, double *out)
{
    double D = (double)(k - aid_k) * Ts;
    double total = 0.0;
    const double *ak = kin_rec_row(r, k) + n_axes, *a0 = kin_rec_row(r, aid_k) + n_axes;
    for (int j = 0; j < n_axes; j++) {
        double x[9];
        memcpy(x, s + 9 * j, sizeof x);
        double e_prior = x[2];
        int known = x[8] < 1.0;
        double moved = ak[j] - a0[j];
        /* conditioned on the candidate's level, the filter's own state unchanged */
        kin_update(x, 2, level[j], R[j] / (double)(len > 1 ? len : 1));
        double lk = leak * (level[j] - e_prior) * D, dr = drift * D, sc = scale * moved;
        double widen = (known ? lk * lk : 0.0) + dr * dr + sc * sc;
        double sd0 = sqrt(kin_pos(x[6])), r_sd0 = sqrt(kin_pos(x[3]));
        double sd = sqrt(sd0 * sd0 + widen);
        out[j] = sign * x[1];
        out[n_axes + j] = sd;
        out[2 * n_axes + j] = x[0];
        out[3 * n_axes + j] = sqrt(r_sd0 * r_sd0 + widen * D * D);
        total += x[1] * x[1] / (sd * sd + sigma2);
    }
    return total;
}

/* erfc(z) = q for 0 < q <= 1 (z >= 0): Halley's steps on erfc from a start near the root, until
   the step is below an ulp of z; a few steps (the convergence is cubic) */
static double kin_erfcinv(double q)
{
    if (q >= 1.0) {
        return 0.0;
    }
    /* erfc(z) ~ exp(-z^2) / (z sqrt(pi)) for large z; near q = 1, erfc(z) ~ 1 - 2 z / sqrt(pi) */
    double z = q > 0.3 ? (1.0 - q) * 0.886226925452758 : sqrt(-log(q));
    for (int it = 0; it < 100; it++) {
        double slope = -1.1283791670955126 * exp(-z * z); /* d erfc / dz */
        double r = (erfc(z) - q) / slope;
        double step = r / (1.0 + z * r);
        z -= step;
        if (fabs(step) <= 2e-16 * fabs(z)) {
            break;
        }
    }
    return z;
}

double acn_chi2_equivalent(double x, int dof)
{
    if (dof == 1 || !isfinite(x)) {
        return x;
    }
    /* the upper tail Q(dof / 2, x / 2) of a chi-square with dof degrees of freedom, in closed form:
       even dof from Q(1, y) = exp(-y), odd from Q(1/2, y) = erfc(sqrt(y)), each step up adding
       y^a exp(-y) / Gamma(a + 1) */
    double y = x / 2.0, tail, term;
    /* a tail below exp(-709.78) is none (as scipy's gammaincc, cephes' igamc, has it) */
    if (y > 0.0 && (dof / 2.0) * log(y) - y - lgamma(dof / 2.0) < -709.782712893384) {
        return INFINITY;
    }
    if (dof % 2) {
        tail = erfc(sqrt(y));
        term = sqrt(y) * exp(-y) / 0.886226925452758; /* Gamma(3/2) */
        for (double a = 0.5; a + 1.0 <= dof / 2.0;) {
            tail += term;
            a += 1.0;
            term *= y / a;
        }
    } else {
        tail = term = exp(-y);
        for (int a = 1; a < dof / 2; a++) {
            term *= y / a;
            tail += term;
        }
    }
    if (tail <= 0.0) {
        return INFINITY;
    }
    double z = kin_erfcinv(tail);
    return 2.0 * z * z;
}

static double kin_jump(int n_axes, const double *s, const double *level)
{
    double sum = 0.0;
    for (int j = 0; j < n_axes; j++) {
        if (sqrt(kin_pos(s[9 * j + 8])) >= 1.0) {
            return 0.0;
        }
    }
    for (int j = 0; j < n_axes; j++) {
        double off = kin_pos(fabs(level[j] - s[9 * j + 2]) - 3.0 * sqrt(kin_pos(s[9 * j + 8])));
        sum += off * off;
    }
    return sqrt(sum);
}

/*
 * A forward side's whole test of a candidate (acn_kin_forward's): s
 * propagated from k0 to k, then as kin_side (sign +1) into out, with
 * res = [its chi-square read on one axis (acn_chi2_equivalent), the level's
 * jump (kin_jump), |v| over the axes, the rms of the sds].
 */
static void kin_test(int n_axes, double *s, acn_kin_rec *r, long k0, long k, double Ts, double q,
                     const double *qv, long aid_k, const double *level, const double *R, long len,
                     double leak, double drift, double scale, double sigma2, double *out,
                     double *res)
{
    kin_to(n_axes, s, r, k0, k, Ts, q, qv);
    long now = k > k0 ? k : k0;
    res[1] = kin_jump(n_axes, s, level);
    double total =
        kin_side(n_axes, s, r, now, aid_k, Ts, level, R, len, leak, drift, scale, sigma2, 1.0, out);
    res[0] = acn_chi2_equivalent(total, n_axes);
    /* rests.py's _norms, its sums in the same order: |v| and the rms of the sds */
    double v2 = 0.0, sd2 = 0.0;
    for (int j = 0; j < n_axes; j++) {
        v2 += out[j] * out[j];
        sd2 += out[n_axes + j] * out[n_axes + j];
    }
    res[2] = sqrt(v2);
    res[3] = sqrt(sd2 / (double)n_axes);
}

void acn_kin_cands(int n_axes, const double *x, const unsigned char *usable, long n_spans,
                   const long *start, const long *stop, const double *R, double *level,
                   double *still)
{
    for (long i = 0; i < n_spans; i++) {
        double *mean = level + i * n_axes;
        long m = 0;
        for (int j = 0; j < n_axes; j++) {
            mean[j] = 0.0;
        }
        for (long k = start[i]; k < stop[i]; k++) {
            if (usable[k]) {
                for (int j = 0; j < n_axes; j++) {
                    mean[j] += x[k * n_axes + j];
                }
                m++;
            }
        }
        if (m <= 1) { /* the mean of none: 0; of one: that row */
            still[i] = 1.0;
            continue;
        }
        for (int j = 0; j < n_axes; j++) {
            mean[j] = mean[j] / (double)m;
        }
        double var_r = 0.0;
        for (int j = 0; j < n_axes; j++) {
            double ss = 0.0;
            for (long k = start[i]; k < stop[i]; k++) {
                if (usable[k]) {
                    double d = x[k * n_axes + j] - mean[j];
                    ss += d * d;
                }
            }
            var_r += ss / (double)m / R[j];
        }
        still[i] = var_r / (double)n_axes;
    }
}

/*
 * A candidate's peak speed (acn_kin_forward's): from the last rest's end
 * e (its velocity u0 and level e0 per axis) to the candidate's start a >= e, on
 * num points of the way (the first e, the last a, rounded half to even between),
 * the velocity integrated from r's V with the level linear
 * from e0 to the candidate's level. out: the peak and the last speed squared,
 * and the peak squared with the level e0 kept all the way.
 */
static void kin_peak(int n_axes, acn_kin_rec *r, double Ts, long e, long a, long num,
                     const double *u0, const double *e0, const double *level, double *out)
{
    /* the points go up from e: each row summed on from the last point's (cur, at sample at), or
       from its checkpoint when that is nearer, without the kept rows' bookkeeping of a read */
    double ve[8], cur[24];
    int w3 = 3 * n_axes;
    memcpy(cur, kin_rec_row(r, e), sizeof(double) * (size_t)w3);
    memcpy(ve, cur, sizeof(double) * (size_t)n_axes);
    long at = e;
    double D = (double)(a - e > 1 ? a - e : 1) * Ts;
    double step = num > 1 ? (double)(a - e) / (double)(num - 1) : 0.0;
    out[0] = out[1] = out[2] = 0.0; /* sums of squares: none below 0 */
    for (long i = 0; i < num; i++) {
        /* np.linspace(e, a, num).round(), as rests.py made it */
        long k = (num > 1 && i == num - 1) ? a : (long)rint((double)i * step + (double)e);
        double tk = (double)(k - e) * Ts;
        double w = tk * tk / (2 * D);
        double s2 = 0.0, f2 = 0.0;
        long base = (k / r->every) * r->every;
        if (at < base || at > k) {
            memcpy(cur, r->cp + (base / r->every) * w3, sizeof(double) * (size_t)w3);
            at = base;
        }
        for (; at < k; at++) { /* V alone (what the points read), as kin_rec_step sums it */
            const double *row = kin_rec_x(r, at);
            for (int j = 0; j < n_axes; j++) {
                cur[j] = cur[j] + row[j] * r->Ts;
            }
        }
        for (int j = 0; j < n_axes; j++) {
            double ramp = (level[j] - e0[j]) * w;
            double v = cur[j] - ve[j] - e0[j] * tk - ramp + u0[j];
            double flat = v + ramp; /* the rest's own level all the way */
            s2 += v * v;
            f2 += flat * flat;
        }
        out[0] = s2 > out[0] ? s2 : out[0];
        out[1] = s2;
        out[2] = f2 > out[2] ? f2 : out[2];
    }
}

int acn_kin_backward(int n_axes, double *s, acn_kin_rec *r, double Ts, double q, const double *qv,
                     const double *R, long m, long n_ev, const long *ev_k, const int *ev_kind,
                     const long *ev_i, const double *ev_z, const double *ev_var,
                     const unsigned char *acc, const double *level, const long *len, double leak,
                     double drift, double scale, double sigma, double *out, double *stat, long *aid,
                     unsigned char *fix)
{
    if (!kin_rec_ready(r) || r->n_axes != n_axes ||
        kin_events_bad(r->n, n_axes, m, n_ev, ev_k, ev_kind, ev_i)) {
        return -1;
    }
    long k_now = 0, aid_k = 0, aid_ev = -1;
    unsigned char fix_seen = 0;
    double var = sigma * sigma;
    for (long e = 0; e < n_ev; e++) {
        long k = ev_k[e], i = ev_i[e];
        int kind = ev_kind[e];
        if (kind == 1 || (kind == 2 && acc[i])) { /* an aid: a fix, or a rest's end */
            kin_aid(n_axes, s, r, k_now, k, Ts, q, qv, kind == 1 ? (int)i : -1, kind == 1 ? 0 : 1,
                    kind == 1 ? ev_z[e] : 0.0, kind == 1 ? ev_var[e] : var);
            k_now = k > k_now ? k : k_now;
            aid_k = k;
            aid_ev = e;
            fix_seen = (unsigned char)(fix_seen || kind == 1);
            continue;
        }
        if (kind != 0) {
            continue;
        }
        kin_to(n_axes, s, r, k_now, k, Ts, q, qv);
        k_now = k > k_now ? k : k_now;
        double *side = out + 4 * n_axes * i, v2 = 0.0, sd2 = 0.0;
        double total = kin_side(n_axes, s, r, k_now, aid_k, Ts, level + i * n_axes, R, len[i], leak,
                                drift, scale, var, -1.0, side);
        /* as kin_test's: the chi-square read on one axis, |v| and the rms of the sds */
        for (int j = 0; j < n_axes; j++) {
            v2 += side[j] * side[j];
            sd2 += side[n_axes + j] * side[n_axes + j];
        }
        stat[3 * i] = acn_chi2_equivalent(total, n_axes);
        stat[3 * i + 1] = sqrt(v2);
        stat[3 * i + 2] = sqrt(sd2 / (double)n_axes);
        aid[i] = aid_ev;
        fix[i] = fix_seen;
        if (acc[i]) {
            kin_aid(n_axes, s, r, k_now, k, Ts, q, qv, -1, 1, 0.0, var);
            aid_k = k;
        }
    }
    return 0;
}

void acn_kin_sums(long n, int n_axes, const double *x, int reverse, double Ts, double *V, double *A,
                  double *W)
{
    for (int j = 0; j < n_axes; j++) {
        V[j] = A[j] = W[j] = 0.0;
    }
    for (long k = 0; k < n; k++) {
        const double *row = x + (reverse ? n - 1 - k : k) * n_axes;
        const double *v = V + k * n_axes, *a = A + k * n_axes, *w = W + k * n_axes;
        for (int j = 0; j < n_axes; j++) {
            /* the first of each numpy cumsum is the term itself; 0 + term is the same double */
            V[(k + 1) * n_axes + j] = v[j] + row[j] * Ts;
            A[(k + 1) * n_axes + j] = a[j] + fabs(row[j]) * Ts;
            W[(k + 1) * n_axes + j] = w[j] + v[j] * Ts;
        }
    }
}

/* ---- the rest decision's forward filter (rests.py, _Decider.forward; fastsmooth.h) ------------
 */

enum { KIN_AXES = 8 }; /* the most axes the forward filter holds on its stack */
enum {
    KIN_CONSISTENT,
    KIN_START,
    KIN_STAND,
    KIN_GATE_OFF,
    KIN_MOVING,
    KIN_LEVEL,
    KIN_CANNOT,
    KIN_NO_DECEL,
    KIN_HYPOTHESIS
};
enum {
    EV_GATE_OFF,
    EV_VETO,
    EV_LEVEL,
    EV_MOVING,
    EV_CONSISTENT,
    EV_START_SD,
    EV_STILL_START,
    EV_NO_REST,
    EV_NOT_STAND,
    EV_STILL_STAND,
    EV_NO_DECEL
};
enum { OUT_NONE, OUT_REFUTED, OUT_WITHIN, OUT_TOO_FEW, OUT_CONFIRMED };

/* what the forward filter knows besides s (rests.py's dict `st`): its sample, its last aid's sample
   and event (-1: none), whether a fix came, and the last rest's and the last stand's end (their
   velocity and level per axis in ends: u, e of the rest, u, e of the stand) */
typedef struct {
    long k, aid_k, src, fix, has_end, end_k, has_stand, stand_k;
} kin_fwd_st;

enum { KIN_MARK_L = 9 }; /* a mark's longs: its event, then kin_fwd_st's eight */

/* the forward filter's whole state: s, st, ends */
typedef struct {
    double s[9 * KIN_AXES];
    double ends[4 * KIN_AXES];
    kin_fwd_st st;
} kin_fwd_state;

static double kin_median(const double *v, long n)
{
    long h = n / 2;
    return n % 2 ? v[h] : (v[h - 1] + v[h]) / 2.0;
}

/* bisect.insort: v (n sorted) gets x after its equals. `ordered`: no NaN among the values v is made
   of, so v is sorted and bisected (the place the scan from the end finds: the first value above x,
   none for a NaN x); else scanned from the end as bisect.insort's list would be (a NaN stops it). A
   record's proven rests are thousands: a scan and a move per value cost O(n) each */
static void kin_insort(double *v, long n, double x, int ordered)
{
    long i = n;
    if (ordered) {
        long lo = 0;
        while (lo < i) {
            long mid = lo + (i - lo) / 2;
            if (v[mid] > x) {
                i = mid;
            } else {
                lo = mid + 1;
            }
        }
    } else {
        while (i > 0 && v[i - 1] > x) {
            i--;
        }
    }
    memmove(v + i + 1, v + i, sizeof(double) * (size_t)(n - i));
    v[i] = x;
}

static int kin_refuses(int reason)
{
    return reason == KIN_MOVING || reason == KIN_LEVEL || reason == KIN_CANNOT ||
           reason == KIN_NO_DECEL;
}

/* the peak speed's figures (kin_peak) of candidate i from the rest that ended at end_k
   with velocity u0 and level e0: peak, end and flat peak speeds */
static void kin_fwd_peak(const acn_kin_fwd *f, long i, long end_k, const double *u0,
                         const double *e0, double *out)
{
    long a = f->start[i] > end_k ? f->start[i] : end_k;
    long num = a - end_k + 1 < f->peak_points ? a - end_k + 1 : f->peak_points;
    kin_peak(f->n_axes, f->rec, f->Ts, end_k, a, num, u0, e0, f->level + i * f->n_axes, out);
    for (int j = 0; j < 3; j++) {
        out[j] = sqrt(out[j]);
    }
}

/* the verdict on candidate i (the reference's judge and other evidence), its side's figures in side
   (4 rows of n_axes) and stat (chi2, |v|, rms sd), jump the level's jump: the reason; the
   evidence's kind and figures into base, flags and num (jump, allowed, moved peak, sd, bound, peak,
   end) */
static int kin_judge(const acn_kin_fwd *f, long i, const kin_fwd_state *w, const double *proven,
                     long n_proven, double jump, const double *side, double chi2, int *base,
                     int *flags, double *num)
{
    int n_axes = f->n_axes;
    double still = f->still[i];
    double moved[3] = {0.0, 0.0, 0.0};
    int have_moved = !w->st.has_end;
    double lk = f->like * (n_proven ? kin_median(proven, n_proven) : 0.0);
    int like = !n_proven || still <= (lk > f->still_k ? lk : f->still_k);
    *flags = like;
    num[0] = jump;
    if (f->gate == 0.0) {
        *base = EV_GATE_OFF;
        return KIN_GATE_OFF;
    }
    if (f->veto[i]) {
        *base = EV_VETO;
        return KIN_MOVING;
    }
    double opt_a = like ? f->level_max : f->unlike * f->level_still, opt_b = f->level_still;
    double allowed = INFINITY;
    if (!(jump <= (opt_b < opt_a ? opt_b : opt_a))) {
        if (!have_moved) {
            kin_fwd_peak(f, i, w->st.end_k, w->ends, w->ends + n_axes, moved);
            have_moved = 1;
        }
        if (like) {
            allowed = moved[0] >= f->motion ? f->level_max : f->level_still;
        } else {
            allowed = moved[2] >= f->motion ? f->unlike * f->level_still : f->level_still;
        }
    }
    if (jump > allowed) {
        num[1] = allowed;
        num[2] = moved[0];
        *base = EV_LEVEL;
        return KIN_LEVEL;
    }
    if (chi2 > f->gate) {
        *base = EV_MOVING;
        return KIN_MOVING;
    }
    /* a piece far less still than the proven rests and shorter than a stand is told only within
       unlike_tell x tell (a trunk mid-stride is that quiet for a tenth of a second); a stand keeps
       tell */
    double dur = (double)(f->stop[i] - f->start[i]) * f->Ts;
    double bound_tell = dur < f->start_s && !like ? f->unlike_tell * f->tell : f->tell;
    int tells = 1, tells_any = 1;
    double sd = side[n_axes];
    for (int j = 0; j < n_axes; j++) {
        double v = side[n_axes + j];
        tells = tells && v <= bound_tell;
        tells_any = tells_any && v <= f->tell;
        if (isnan(v) || isnan(sd)) { /* np.max keeps a NaN */
            sd = NAN;
        } else if (v > sd) {
            sd = v;
        }
    }
    if (tells) {
        *base = EV_CONSISTENT;
        return KIN_CONSISTENT;
    }
    num[3] = sd;
    num[7] = bound_tell;
    if (bound_tell < f->tell && tells_any) {
        *flags |= 4; /* the words say the bound refused it */
    }
    if (!w->st.has_end) {
        if (f->start_sd > f->tell) {
            *base = EV_START_SD;
            return KIN_CANNOT;
        }
        if ((double)f->start[i] * f->Ts <= f->start_within_s && dur >= f->start_s &&
            still <= f->still_k) {
            *base = EV_STILL_START;
            return KIN_START;
        }
        *base = EV_NO_REST;
        return KIN_CANNOT;
    }
    double bound = f->still_k;
    if (n_proven) {
        double twice = 2.0 * kin_median(proven, n_proven);
        bound = twice > f->still_k ? twice : f->still_k;
    }
    num[4] = bound;
    if (dur < f->start_s || still > bound) {
        *base = EV_NOT_STAND;
        return KIN_CANNOT;
    }
    double stand[3];
    if (w->st.has_stand) {
        kin_fwd_peak(f, i, w->st.stand_k, w->ends + 2 * n_axes, w->ends + 3 * n_axes, stand);
    } else {
        if (!have_moved) {
            kin_fwd_peak(f, i, w->st.end_k, w->ends, w->ends + n_axes, moved);
        }
        memcpy(stand, moved, sizeof stand);
    }
    num[5] = stand[0];
    num[6] = stand[1];
    if (stand[1] <= f->rel * stand[0] && stand[0] >= 2.0 * sd) {
        *base = EV_STILL_STAND;
        return KIN_STAND;
    }
    *base = EV_NO_DECEL;
    return KIN_NO_DECEL;
}

/* the mark of slot `slot` made (save) or read back (!save): its event e and the state */
static void kin_fwd_mark(const acn_kin_fwd *f, acn_kin_fwd_out *o, long slot, long *e,
                         kin_fwd_state *w, int save)
{
    long *ml = o->mark_l + KIN_MARK_L * slot;
    double *md = o->mark_d + 13 * f->n_axes * slot;
    size_t ns = sizeof(double) * 9 * (size_t)f->n_axes, ne = sizeof(double) * 4 * (size_t)f->n_axes;
    long *fields[8] = {&w->st.k,       &w->st.aid_k, &w->st.src,       &w->st.fix,
                       &w->st.has_end, &w->st.end_k, &w->st.has_stand, &w->st.stand_k};
    if (save) {
        ml[0] = *e;
        for (int j = 0; j < 8; j++) {
            ml[1 + j] = *fields[j];
        }
        memcpy(md, w->s, ns);
        memcpy(md + 9 * f->n_axes, w->ends, ne);
        o->mark_ok[slot] = 1;
    } else {
        *e = ml[0];
        for (int j = 0; j < 8; j++) {
            *fields[j] = ml[1 + j];
        }
        memcpy(w->s, md, ns);
        memcpy(w->ends, md + 9 * f->n_axes, ne);
    }
}

/* the inputs' lengths and indices: 0 when every one lies within its array */
static int kin_fwd_checked(const acn_kin_fwd *f, long resume, const acn_kin_fwd_out *o)
{
    if (!kin_rec_ready(f->rec) || f->rec->n != f->n || f->rec->n_axes != f->n_axes) {
        return -1;
    }
    if (f->n_axes < 1 || f->n_axes > KIN_AXES || f->n < 0 || f->m < 0 || f->n_ev < 0 ||
        f->mark_every < 1 || f->n_marks != f->m / f->mark_every + 1 || f->peak_points < 1 ||
        resume < -1 || resume >= f->m || (resume >= 0 && resume % f->mark_every != 0)) {
        return -1;
    }
    if (resume >= 0 && !o->mark_ok[resume / f->mark_every]) {
        return -1;
    }
    for (long i = 0; i < f->m; i++) { /* in time order, within the record: tests come in order */
        if (f->start[i] < 0 || f->stop[i] <= f->start[i] || f->stop[i] > f->n ||
            (i > 0 && f->start[i] <= f->start[i - 1])) {
            return -1;
        }
    }
    if (kin_events_bad(f->n, f->n_axes, f->m, f->n_ev, f->ev_k, f->ev_kind, f->ev_i)) {
        return -1;
    }
    /* each candidate tested once, in order, at its start, and ended at its last sample after its
       test: the restore (kin_fwd_restore) and the proven list (2 m doubles of work) rely on it */
    long tested = 0;
    for (long e = 0; e < f->n_ev; e++) {
        long i = f->ev_i[e];
        if (f->ev_kind[e] == 0 && (i != tested++ || f->ev_k[e] != f->start[i])) {
            return -1;
        }
        if (f->ev_kind[e] == 2 && (i >= tested || f->ev_k[e] != f->stop[i] - 1)) {
            return -1;
        }
    }
    if (tested != f->m) {
        return -1;
    }
    if (resume >=
        0) { /* the mark resumed from: saved at that candidate's test, its samples in the record */
        const long *ml = o->mark_l + KIN_MARK_L * (resume / f->mark_every);
        long e = ml[0], k = ml[1], aid_k = ml[2], src = ml[3], end_k = ml[6], stand_k = ml[8];
        if (e < 0 || e >= f->n_ev || f->ev_kind[e] != 0 || f->ev_i[e] != resume || k < 0 ||
            k > f->n || aid_k < 0 || aid_k > f->n || src < -1 || src >= f->n_ev || end_k < 0 ||
            end_k > f->n || stand_k < 0 || stand_k > f->n) {
            return -1;
        }
    }
    return 0;
}

/* back to before the hypothesis h (the state saved in saved, its event e_h): the candidates after
   it undone, h kept as refused; returns the event to go on from. Only h .. last (the last candidate
   tested) can have been marked since: tests come in candidate order, and every candidate after the
   last tested is unmarked (by the pass' start or an earlier restore), so the rest of the m are not
   walked (a drive's thousands of hypotheses each walked all 60 000) */
static long kin_fwd_restore(acn_kin_fwd_out *o, long last, long h, long e_h, kin_fwd_state *w,
                            const kin_fwd_state *saved, double *proven, long *n_proven,
                            const double *saved_proven, long saved_n_proven)
{
    *w = *saved;
    *n_proven = saved_n_proven;
    memcpy(proven, saved_proven, sizeof(double) * (size_t)saved_n_proven);
    for (long j = h; j <= last; j++) {
        o->acc[j] = 0;
        if (j > h) {
            o->proven[j] = 0;
        }
    }
    return e_h;
}

long acn_kin_forward(const acn_kin_fwd *f, long resume, acn_kin_fwd_out *o)
{
    if (kin_fwd_checked(f, resume, o)) {
        return -1;
    }
    int n_axes = f->n_axes;
    long m = f->m, e = 0, n_proven = 0;
    double *proven = o->work, *saved_proven = o->work + m;
    double var = f->sigma * f->sigma;
    kin_fwd_state w, saved;
    memset(&w, 0, sizeof w);
    memset(&saved, 0, sizeof saved);
    w.st.src = -1;
    if (resume < 0) {
        for (int j = 0; j < n_axes; j++) {
            double *x = w.s + 9 * j;
            x[3] = f->diffuse[0];
            x[6] = f->diffuse[1];
            x[8] = f->diffuse[2];
        }
        resume = 0;
        memset(o->mark_ok, 0, (size_t)f->n_marks);
    } else {
        long slot = resume / f->mark_every;
        kin_fwd_mark(f, o, slot, &e, &w, 0);
        memset(o->mark_ok + slot + 1, 0, (size_t)(f->n_marks - slot - 1));
    }
    int ordered = 1; /* no NaN stillness: the proven ones stay sorted, bisected (kin_insort) */
    for (long i = 0; i < m; i++) {
        ordered = ordered && !isnan(f->still[i]);
    }
    /* the verdicts before the mark stand: their accepted rests and proven stillness carry on */
    for (long i = 0; i < m; i++) {
        if (i >= resume) {
            o->acc[i] = o->proven[i] = 0;
        } else if (o->proven[i]) {
            kin_insort(proven, n_proven++, f->still[i], ordered);
        }
        o->tried[i] = 0;
    }
    /* the hypothesis open: its candidate, the event after its test, its confirmations, the
       candidates seen with it; the state before it in saved */
    long h = -1, e_h = 0, count = 0, seen = 0, saved_n_proven = 0, last = -1;
    double res[4];
    while (e < f->n_ev || h >= 0) {
        if (e == f->n_ev) { /* the record ended before the hypothesis was borne out */
            o->tried[h] = 1;
            o->reason[h] = KIN_CANNOT;
            o->outcome[h] = OUT_TOO_FEW;
            e = kin_fwd_restore(o, last, h, e_h, &w, &saved, proven, &n_proven, saved_proven,
                                saved_n_proven);
            h = -1;
            continue;
        }
        long k = f->ev_k[e], i = f->ev_i[e];
        int kind = f->ev_kind[e];
        e++;
        if (kind == 1) {
            kin_aid(n_axes, w.s, f->rec, w.st.k, k, f->Ts, f->q, f->qv, (int)i, 0, f->ev_z[e - 1],
                    f->ev_var[e - 1]);
            w.st.k = k > w.st.k ? k : w.st.k;
            w.st.aid_k = k;
            w.st.src = e - 1;
            w.st.fix = 1;
            continue;
        }
        if (kind == 0 && h < 0 && i % f->mark_every == 0) {
            long at = e - 1;
            kin_fwd_mark(f, o, i / f->mark_every, &at, &w, 1);
        }
        if (kind == 2) {
            if (o->acc[i]) {
                kin_aid(n_axes, w.s, f->rec, w.st.k, k, f->Ts, f->q, f->qv, -1, 1, 0.0, var);
                w.st.k = k > w.st.k ? k : w.st.k;
                w.st.aid_k = k;
                w.st.has_end = 1;
                w.st.end_k = k;
                for (int j = 0; j < n_axes; j++) {
                    w.ends[j] = w.s[9 * j + 1];
                    w.ends[n_axes + j] = w.s[9 * j + 2];
                }
                if ((double)(f->stop[i] - f->start[i]) * f->Ts >= f->start_s) {
                    w.st.has_stand = 1;
                    w.st.stand_k = k;
                    memcpy(w.ends + 2 * n_axes, w.ends, sizeof(double) * 2 * (size_t)n_axes);
                }
                w.st.src = e - 1;
            }
            continue;
        }
        /* a candidate's test: its side, then the verdict */
        last = i;
        double *side = o->side + 4 * n_axes * i, *num = o->num + ACN_KIN_NUM * i;
        kin_test(n_axes, w.s, f->rec, w.st.k, k, f->Ts, f->q, f->qv, w.st.aid_k,
                 f->level + n_axes * i, f->R, f->stop[i] - f->start[i], f->leak, f->drift, f->scale,
                 var, side, res);
        w.st.k = k > w.st.k ? k : w.st.k;
        o->stat[3 * i] = res[0];
        o->stat[3 * i + 1] = res[2];
        o->stat[3 * i + 2] = res[3];
        o->aid[i] = w.st.src;
        o->fix[i] = (unsigned char)w.st.fix;
        o->outcome[i] = OUT_NONE;
        int reason = kin_judge(f, i, &w, proven, n_proven, res[1], side, res[0], &o->base[i],
                               &o->flags[i], num);
        if (reason == KIN_CONSISTENT || reason == KIN_START) {
            kin_insort(proven, n_proven++, f->still[i], ordered);
            o->proven[i] = 1;
        }
        o->reason[i] = reason;
        if (h >= 0) {
            seen++;
            if (kin_refuses(reason) || seen > f->within) { /* it fails: on without it */
                o->tried[h] = 1;
                o->reason[h] = o->reason[h] == KIN_CONSISTENT ? KIN_LEVEL : KIN_CANNOT;
                o->outcome[h] = kin_refuses(reason) ? OUT_REFUTED : OUT_WITHIN;
                o->oarg[2 * h] = i;
                o->oarg[2 * h + 1] = reason;
                e = kin_fwd_restore(o, last, h, e_h, &w, &saved, proven, &n_proven, saved_proven,
                                    saved_n_proven);
                h = -1;
                continue;
            }
            /* a move before the first rest or for a level that moved; a stride's where the record
               lost the rests it had */
            int lost = saved.st.has_end && o->reason[h] != KIN_CONSISTENT;
            double moved[3] = {0.0, 0.0, 0.0};
            if (w.st.has_end) {
                kin_fwd_peak(f, i, w.st.end_k, w.ends, w.ends + n_axes, moved);
            }
            if (moved[0] >= (lost ? f->stride : f->motion)) {
                count++;
            }
            if (count >= f->confirm) {
                o->outcome[h] = OUT_CONFIRMED;
                o->oarg[2 * h + 1] = o->reason[h];
                o->reason[h] = KIN_CONSISTENT;
                h = -1;
            }
        } else if (!o->tried[i] && f->gate > 0.0 &&
                   (reason == KIN_CANNOT ||
                    (reason == KIN_CONSISTENT && res[1] > f->level_still))) {
            /* a hypothesis, the filter saved as it stands before it */
            h = i;
            e_h = e;
            count = seen = 0;
            saved = w;
            saved_n_proven = n_proven;
            memcpy(saved_proven, proven, sizeof(double) * (size_t)n_proven);
            if (reason == KIN_CONSISTENT) {
                o->flags[i] |= 2; /* its level moved */
            } else {
                reason = o->reason[i] = KIN_HYPOTHESIS;
            }
        }
        if (reason <= KIN_GATE_OFF || reason == KIN_HYPOTHESIS) {
            o->acc[i] = 1;
            kin_aid(n_axes, w.s, f->rec, w.st.k, k, f->Ts, f->q, f->qv, -1, 1, 0.0, var);
            w.st.k = k > w.st.k ? k : w.st.k;
            w.st.aid_k = k;
        }
    }
    return 0;
}

/* the prefix sum C[m] = x[0] + ... + x[m-1] of column j (stride n_axes), one row on: numpy's
   cumsum, whose first term is x[0] itself (not 0 + x[0]) */
static double rest_prefix_step(double c, long m, const double *x, int n_axes, int j, int square)
{
    double v = x[m * n_axes + j];
    if (square)
        v = v * v;
    return m == 0 ? v : c + v;
}

/* axis j's window sums brought to window i (rows i .. i + w - 1): st[0..1] the trailing prefix sums
   C[i] (of x and x^2), st[2..3] the leading ones C[i + w], *at the window they hold (-1: none yet).
   Stepped row by row from where they are, as one pass over the record steps them, so the same
   doubles whatever the windows asked for (in order) */
static void rest_window_to(const double *x, int n_axes, int j, long w, long i, double *st, long *at)
{
    if (*at < 0) { /* zupt.py starts both sums from np.zeros */
        st[0] = st[1] = st[2] = st[3] = 0.0;
        for (long m = 0; m < w; m++) {
            st[2] = rest_prefix_step(st[2], m, x, n_axes, j, 0);
            st[3] = rest_prefix_step(st[3], m, x, n_axes, j, 1);
        }
        *at = 0;
    }
    for (long k = *at + 1; k <= i; k++) {
        st[2] = rest_prefix_step(st[2], k + w - 1, x, n_axes, j, 0);
        st[3] = rest_prefix_step(st[3], k + w - 1, x, n_axes, j, 1);
        st[0] = rest_prefix_step(st[0], k - 1, x, n_axes, j, 0);
        st[1] = rest_prefix_step(st[1], k - 1, x, n_axes, j, 1);
    }
    if (i > *at)
        *at = i;
}

static double rest_window_var(const double *st, long w, double *mean)
{
    *mean = (st[2] - st[0]) / (double)w;
    return ((st[3] - st[1]) - (double)w * (*mean * *mean)) / (double)(w - 1);
}

long acn_rest_centres(long n, int n_axes, const double *x, const unsigned char *usable, long w,
                      const double *allow, double var_k, double *state, long *at,
                      unsigned char *centre)
{
    if (n < 0 || n_axes < 1 || w < 1 || w % 2 == 0 || n > LONG_MAX / n_axes)
        return -1;
    for (int j = 0; j < n_axes;
         j++) /* a whole pass: from fresh sums (a state held would be skipped) */
        if (at[j] >= 0)
            return -1;
    long h = w / 2;
    for (long k = 0; k < n; k++)
        centre[k] = 0;
    if (n < w)
        return 0;
    long bad = 0; /* unusable rows in the window: a count, exact as numpy's sum of 0s and 1s */
    for (long m = 0; m < w; m++)
        bad += usable[m] ? 0 : 1;
    for (long i = 0; i + w <= n; i++) {
        if (i > 0)
            bad += (usable[i + w - 1] ? 0 : 1) - (usable[i - 1] ? 0 : 1);
        double quiet = 0.0, mean;
        for (int j = 0; j < n_axes;
             j++) { /* summed over the axes in their order, as numpy's += per axis */
            rest_window_to(x, n_axes, j, w, i, state + 4 * j, at + j);
            quiet += rest_window_var(state + 4 * j, w, &mean) / allow[j];
        }
        centre[h + i] = bad == 0 && quiet / (double)n_axes <= var_k;
    }
    return 0;
}

long acn_rest_span(long n, int n_axes, const double *x, long w, long lo, long hi, double *state,
                   long *at, double *means, double *wvar)
{
    long h = w / 2;
    if (n < 0 || n_axes < 1 || w < 1 || w % 2 == 0 || n > LONG_MAX / n_axes || lo < h || hi < lo ||
        hi > n - h)
        return -1;
    for (int j = 0; j < n_axes; j++)
        if (at[j] > lo - h)
            return -1;
    for (long c = lo; c < hi; c++)
        wvar[c - lo] = 0.0;
    for (int j = 0; j < n_axes; j++) {
        for (long c = lo; c < hi; c++) {
            double mean;
            rest_window_to(x, n_axes, j, w, c - h, state + 4 * j, at + j);
            double v = rest_window_var(state + 4 * j, w, &mean);
            means[(c - lo) * n_axes + j] = mean;
            wvar[c - lo] += v;
        }
    }
    return 0;
}

long acn_rest_prepare(long n, int n_axes, int j, const double *accel, const unsigned char *clipped,
                      const double *powers, double eps_mean, double c1, double *x,
                      unsigned char *ok)
{
    if (n < 0 || n_axes < 1 || j < 0 || j >= n_axes || n > LONG_MAX / n_axes)
        return -1;
    for (long k = 0; k < n; k++) {
        long i = k * n_axes + j;
        double a = accel[i];
        int good = !clipped[i] && isfinite(a);
        ok[i] = (unsigned char)good;
        x[i] = good ? a - (eps_mean - c1 * powers[k]) : 0.0;
    }
    return 0;
}
