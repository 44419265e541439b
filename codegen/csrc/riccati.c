/* The C twin of the Python in codegen/gains.py and codegen/bounds.py: see riccati.h. */
#include "riccati.h"
#include <math.h>
#define AB(x) fabs(x)
#define MX(m, x)                                                                                   \
    do {                                                                                           \
        double t_ = AB(x);                                                                         \
        if (t_ > (m))                                                                              \
            (m) = t_;                                                                              \
    } while (0)

/* P = F P F' + Q on the entries carried (right-hand sides read the old values) */
#define RIC_PREDICT                                                                                \
    do {                                                                                           \
        double nrr = prr + 2 * Ts * pru + Ts * Ts * puu + 2 * h2 * pra + 2 * Ts * h2 * pua +       \
                     h2 * h2 * paa + qrr;                                                          \
        double nru = pru + Ts * puu + h2 * pua + Ts * (pra + Ts * pua + h2 * paa) + qru;           \
        double nuu = puu + 2 * Ts * pua + Ts * Ts * paa + quu;                                     \
        double nra = pra + Ts * pua + h2 * paa + qra;                                              \
        double nre = phi * (pre + Ts * pue + h2 * pae);                                            \
        double nua = pua + Ts * paa + qua;                                                         \
        double nue = phi * (pue + Ts * pae);                                                       \
        prr = nrr;                                                                                 \
        pru = nru;                                                                                 \
        puu = nuu;                                                                                 \
        pra = nra;                                                                                 \
        pre = nre;                                                                                 \
        pua = nua;                                                                                 \
        pue = nue;                                                                                 \
        paa = paa + qaa;                                                                           \
        pae = phi * pae;                                                                           \
        pee = phi2 * pee + qee;                                                                    \
    } while (0)
/* K = c / S, P = P - K c' */
#define RIC_UPDATE                                                                                 \
    do {                                                                                           \
        kr = cr / S;                                                                               \
        ku = cu / S;                                                                               \
        ka = ca / S;                                                                               \
        ke = ce / S;                                                                               \
        prr -= kr * cr;                                                                            \
        pru -= kr * cu;                                                                            \
        puu -= ku * cu;                                                                            \
        pra -= kr * ca;                                                                            \
        pua -= ku * ca;                                                                            \
        paa -= ka * ca;                                                                            \
        pre -= kr * ce;                                                                            \
        pue -= ku * ce;                                                                            \
        pae -= ka * ce;                                                                            \
        pee -= ke * ce;                                                                            \
    } while (0)
#define RIC_STATE                                                                                  \
    double Ts = par[0], phi = par[1], qaa = par[2], qua = par[3], qra = par[4], qee = par[5];      \
    double quu = par[6], qru = par[7], qrr = par[8], R = par[9];                                   \
    double h2 = Ts * Ts / 2.0, phi2 = phi * phi;                                                   \
    double prr = P0[0], pru = P0[1], puu = P0[5];                                                  \
    double pra = P0[2], pua = P0[6], paa = P0[10], pre = P0[3], pue = P0[7], pae = P0[11],         \
           pee = P0[15]
/* rows: sorted sample indices (nrows of them) whose prior P (16), K, sig and S are stored; ext:
 * kmax[4], sigma_max[4], S_min, S_max. K, sig, S_all: the first `keep` samples. */
void acn_riccati(long n, const double *par, const double *P0, const unsigned char *valid, long keep,
                 long nrows, const long *rows, double *K, double *sig, double *S_all,
                 double *mprior, double *mpost, double *mc, double *rowP, double *rowK,
                 double *rowsig, double *rowS, double *ext)
{
    RIC_STATE;
    long k, ir = 0;
    int i;
    double vmax[4] = {0.0, 0.0, 0.0, 0.0};
    for (i = 0; i < 7; ++i) {
        mprior[i] = 0.0;
        mpost[i] = 0.0;
    }
    for (i = 0; i < 4; ++i) {
        mc[i] = 0.0;
        ext[i] = 0.0;
        ext[4 + i] = 0.0;
    }
    ext[8] = HUGE_VAL;
    ext[9] = 0.0;
    for (k = 0; k < n; ++k) {
        double cr, cu, ca, ce, S, kr, ku, ka, ke, sg[4];
        int row = ir < nrows && rows[ir] == k;
        if (k) {
            RIC_PREDICT;
        }
        MX(mprior[0], pra);
        MX(mprior[1], pua);
        MX(mprior[2], paa);
        MX(mprior[3], pre);
        MX(mprior[4], pue);
        MX(mprior[5], pae);
        MX(mprior[6], pee);
        if (row) {
            double P[16] = {prr, pru, pra, pre, pru, puu, pua, pue,
                            pra, pua, paa, pae, pre, pue, pae, pee};
            for (i = 0; i < 16; ++i) {
                rowP[16 * ir + i] = P[i];
            }
        }
        cr = pra + pre;
        cu = pua + pue;
        ca = paa + pae;
        ce = pae + pee;
        MX(mc[0], cr);
        MX(mc[1], cu);
        MX(mc[2], ca);
        MX(mc[3], ce);
        S = ca + ce + R;
        if (valid == 0 || valid[k]) {
            RIC_UPDATE;
        } else {
            kr = ku = ka = ke = 0.0;
        }
        /* sigma only where it is stored; its maximum from the variances (sqrt is monotonic) */
        if (prr > vmax[0]) {
            vmax[0] = prr;
        }
        if (puu > vmax[1]) {
            vmax[1] = puu;
        }
        if (paa > vmax[2]) {
            vmax[2] = paa;
        }
        if (pee > vmax[3]) {
            vmax[3] = pee;
        }
        if (k < keep || row) {
            sg[0] = sqrt(prr > 0.0 ? prr : 0.0);
            sg[1] = sqrt(puu > 0.0 ? puu : 0.0);
            sg[2] = sqrt(paa > 0.0 ? paa : 0.0);
            sg[3] = sqrt(pee > 0.0 ? pee : 0.0);
        }
        MX(ext[0], kr);
        MX(ext[1], ku);
        MX(ext[2], ka);
        MX(ext[3], ke);
        if (S < ext[8]) {
            ext[8] = S;
        }
        if (S > ext[9]) {
            ext[9] = S;
        }
        if (k < keep) {
            K[4 * k] = kr;
            K[4 * k + 1] = ku;
            K[4 * k + 2] = ka;
            K[4 * k + 3] = ke;
            for (i = 0; i < 4; ++i) {
                sig[4 * k + i] = sg[i];
            }
            S_all[k] = S;
        }
        if (row) {
            rowK[4 * ir] = kr;
            rowK[4 * ir + 1] = ku;
            rowK[4 * ir + 2] = ka;
            rowK[4 * ir + 3] = ke;
            for (i = 0; i < 4; ++i) {
                rowsig[4 * ir + i] = sg[i];
            }
            rowS[ir] = S;
            ++ir;
        }
        MX(mpost[0], pra);
        MX(mpost[1], pua);
        MX(mpost[2], paa);
        MX(mpost[3], pre);
        MX(mpost[4], pue);
        MX(mpost[5], pae);
        MX(mpost[6], pee);
        MX(mc[0], pra + pre);
        MX(mc[1], pua + pue);
        MX(mc[2], paa + pae);
        MX(mc[3], pae + pee);
    }
    for (i = 0; i < 4; ++i) {
        ext[4 + i] = sqrt(vmax[i]);
    }
}

/* The stated bound's predict of one sample, shared by acn_bound and acn_bound_loop: eps' error
 * through its decay (none at sample 0: later is 0), then r's and v's through a's. */
#define BOUND_PREDICT(later)                                                                       \
    do {                                                                                           \
        if (later) {                                                                               \
            Esm = Es + omp * Ee + d_dec;                                                           \
            Eem = phi * Ee + d_dec;                                                                \
        } else {                                                                                   \
            Esm = Es;                                                                              \
            Eem = Ee;                                                                              \
        }                                                                                          \
        a_c = a_prev + Ea;                                                                         \
        Er = Er + Ev + H2 * Ea + dH2 * a_c + rfl;                                                  \
        Ev = Ev + T2 * Ea + dT2 * a_c + vfl;                                                       \
    } while (0)

/* The data-free stated bound of codegen.bounds.error_bound (covariance form, every sample valid,
 * |y| <= ysig sqrt(S), |a| <= a_abs), the same recursion in the same order, fed by the Riccati
 * above sample by sample: its cost is constant per sample and nothing is stored but the asked-for
 * rows. bp: omp, Ts, dz + d_y, d_a, d_e, d_dec, dH2, dT2, r floors, v floors, a_abs, ysig, dS, R,
 * 2^-22, Ee0, dc[4], lsbK[4], lsb_w / 2 (the rounding of w = y / S enters as S lsb_w / 2 of
 * innovation error). out: (nrows, 4) [r, u, a, eps]. */
void acn_bound(long n, const double *par, const double *P0, const double *bp, long nrows,
               const long *rows, double *out)
{
    RIC_STATE;
    double omp = bp[0], inj = bp[2], d_a = bp[3], d_e = bp[4], d_dec = bp[5], dH2 = bp[6],
           dT2 = bp[7];
    double rfl = bp[8], vfl = bp[9], a_abs = bp[10], ysig = bp[11], dS = bp[12], Rq = bp[13],
           k22 = bp[14];
    const double *dc = bp + 16, *lsbK = bp + 20, lw = bp[24];
    double H2 = Ts * Ts / 2, T2 = Ts * Ts;
    double Es = 0.0, Ee = bp[15], Ea, Ev = 0.0, Er = 0.0, a_prev = 0.0, Esm, Eem;
    long k, ir = 0;
    Ea = Ee;
    for (k = 0; k < n; ++k) {
        double cr, cu, ca, ce, S, kr, ku, ka, ke, Kc[4], dK[4], yc, a_c, injk;
        int i;
        if (k) {
            RIC_PREDICT;
        }
        cr = pra + pre;
        cu = pua + pue;
        ca = paa + pae;
        ce = pae + pee;
        S = ca + ce + R;
        RIC_UPDATE;
        Kc[0] = kr;
        Kc[1] = ku * Ts;
        Kc[2] = ka;
        Kc[3] = ke;
        for (i = 0; i < 4; ++i) {
            double ak = fabs(Kc[i]);
            dK[i] = (dc[i] + ak * dS) / Rq + ak * k22 + lsbK[i];
        }
        BOUND_PREDICT(k);
        injk = inj + S * lw;
        yc = ysig * sqrt(S) + Esm + injk;
        Es = fabs(1.0 - Kc[2] - Kc[3]) * Esm + fabs(Kc[2] + Kc[3]) * injk + (dK[2] + dK[3]) * yc +
             d_a + d_e;
        Ee = Eem + fabs(Kc[3]) * (Esm + injk) + dK[3] * yc + d_e;
        Ev += fabs(Kc[1]) * (Esm + injk) + dK[1] * yc;
        Er += fabs(Kc[0]) * (Esm + injk) + dK[0] * yc;
        Ea = Es + Ee;
        a_prev = a_abs;
        if (ir < nrows && rows[ir] == k) {
            out[4 * ir] = Er;
            out[4 * ir + 1] = Ev / Ts;
            out[4 * ir + 2] = Ea;
            out[4 * ir + 3] = Ee;
            ++ir;
        }
    }
}

/* codegen.bounds.error_bound's recursion over m samples given its per-sample inputs (K, dK (m, 4)
 * in C coordinates, |y|, |a|, the w injection, valid): the same operations in the same order as its
 * Python loop, so the same doubles. bp: omp, phi, d_dec, H2, T2, dH2, dT2, r floor, v floor, dz,
 * d_y, d_a, d_e, Ts. st: Es, Ee, Ea, Ev, Er, a_prev in, and out at the end; k0 the first sample's
 * index. out: (m, 4). */
void acn_bound_loop(long m, long k0, const double *bp, const double *K, const double *dK,
                    const double *y, const double *a, const double *dw, const unsigned char *valid,
                    double *st, double *out)
{
    double omp = bp[0], phi = bp[1], d_dec = bp[2], H2 = bp[3], T2 = bp[4], dH2 = bp[5],
           dT2 = bp[6];
    double rfl = bp[7], vfl = bp[8], dz = bp[9], d_y = bp[10], d_a = bp[11], d_e = bp[12],
           Ts = bp[13];
    double Es = st[0], Ee = st[1], Ea = st[2], Ev = st[3], Er = st[4], a_prev = st[5];
    long k;
    for (k = 0; k < m; ++k) {
        double Esm, Eem, a_c;
        BOUND_PREDICT(k + k0);
        if (valid[k]) {
            const double *Kk = K + 4 * k, *dKk = dK + 4 * k;
            double inj = dz + d_y + dw[k];
            double yc = y[k] + Esm + inj;
            Es = fabs(1.0 - Kk[2] - Kk[3]) * Esm + fabs(Kk[2] + Kk[3]) * inj +
                 (dKk[2] + dKk[3]) * yc + d_a + d_e;
            Ee = Eem + fabs(Kk[3]) * (Esm + inj) + dKk[3] * yc + d_e;
            Ev += fabs(Kk[1]) * (Esm + inj) + dKk[1] * yc;
            Er += fabs(Kk[0]) * (Esm + inj) + dKk[0] * yc;
        } else {
            Es = Esm;
            Ee = Eem;
        }
        Ea = Es + Ee;
        a_prev = a[k];
        out[4 * k] = Er;
        out[4 * k + 1] = Ev / Ts;
        out[4 * k + 2] = Ea;
        out[4 * k + 3] = Ee;
    }
    st[0] = Es;
    st[1] = Ee;
    st[2] = Ea;
    st[3] = Ev;
    st[4] = Er;
    st[5] = a_prev;
}

/* codegen.gains._cone and the search of schedule() over m samples at once: the longest segment from
 * the accumulators A (as doubles) whose every gain keeps an integer in its interval. K: (m, 4) the
 * float64 gains in C coordinates, row t = sample t of the segment (row 0 its start, sample k0 of
 * the run); each in accumulator LSB, Kq = K / unit, with the tolerance of schedule()'s q_of, the
 * same doubles: max(rel w |Kq|, floor) + half, w = clip((k0 + t + 1) / ramp, 0.05, 1) for K_r, K_v
 * (1 without a ramp). par: unit[4], rel[4], floor[4], half[4], ramp, k0. hold[i]: a held gain (its
 * value within tolerance at t = 0 .. L - 1), otherwise linear (its slope s: A + s t within
 * tolerance at t = 1 .. L). lohi: in, the intervals of the lengths below L0 (4 lo then 4 hi); out,
 * those of the longest length found. Returns that length, at most m - 1 (L0 - 1 if even L0 does not
 * fit). */
static void cone_q(const double *K, const double *par, long t, int i, double *kq, double *tq)
{
    double ramp = par[16], w = 1.0, r, x;
    *kq = K[4 * t + i] / par[i];
    r = par[4 + i];
    if (ramp > 0.0 && par[17] < ramp && i < 2) {
        w = ((double)((long)par[17] + t) + 1.0) / ramp;
        w = w < 0.05 ? 0.05 : (w > 1.0 ? 1.0 : w);
        r = r * w;
    }
    x = r * fabs(*kq);
    *tq = (x > par[8 + i] ? x : par[8 + i]) + par[12 + i];
}

long acn_cone(long m, long L0, const double *K, const double *par, const double *A,
              const unsigned char *hold, double *lohi)
{
    double lo[4], hi[4];
    long L;
    int i;
    for (i = 0; i < 4; ++i) {
        lo[i] = lohi[i];
        hi[i] = lohi[4 + i];
    }
    for (L = L0; L < m; ++L) {
        double nlo[4], nhi[4];
        for (i = 0; i < 4; ++i) {
            double l, h, kq, tq;
            if (hold[i]) {
                cone_q(K, par, L - 1, i, &kq, &tq);
                l = kq - tq;
                h = kq + tq;
            } else {
                double d;
                cone_q(K, par, L, i, &kq, &tq);
                d = kq - A[i];
                l = (d - tq) / (double)L;
                h = (d + tq) / (double)L;
            }
            nlo[i] = l > lo[i] ? l : lo[i];
            nhi[i] = h < hi[i] ? h : hi[i];
            if (ceil(nlo[i]) > floor(nhi[i])) {
                break;
            }
        }
        if (i < 4) {
            break;
        }
        for (i = 0; i < 4; ++i) {
            lo[i] = nlo[i];
            hi[i] = nhi[i];
        }
    }
    for (i = 0; i < 4; ++i) {
        lohi[i] = lo[i];
        lohi[4 + i] = hi[i];
    }
    return L - 1;
}

/* schedule()'s account of m samples: the stored gain of gain i at sample t is the high word (>>
 * ex[i]) of acc = A[i] + sl[i] t (sl[i] = 0: A[i] throughout); err = |hi lsb - K| (the same doubles
 * as numpy). maxerr[4] updated; head (nhead, 4): the errors of the first nhead samples. Returns 0,
 * or 1 + the first gain whose high word leaves int32. */
int acn_account(long m, const long long *A, const long long *sl, const long long *ex,
                const double *lsb, const double *K, double *maxerr, long nhead, double *head)
{
    long t;
    int i;
    for (t = 0; t < m; ++t) {
        for (i = 0; i < 4; ++i) {
            long long hi = (A[i] + sl[i] * (long long)t) >> ex[i];
            double e;
            if (hi > 2147483647LL || hi < -2147483647LL) {
                return 1 + i;
            }
            e = fabs((double)hi * lsb[i] - K[4 * t + i]);
            if (e > maxerr[i]) {
                maxerr[i] = e;
            }
            if (t < nhead) {
                head[4 * t + i] = e;
            }
        }
    }
    return 0;
}
