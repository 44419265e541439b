"""Float64 gain sequence of one axis and its compressed schedule.

The gain of the filter does not depend on the data, only on the design and
on which samples are skipped. :func:`riccati` runs the Riccati recursion of
DESIGN.md restricted to the seven entries of P the gain needs (P_ra, P_ua,
P_aa, P_re, P_ue, P_ae, P_ee); P_rr, P_uu and P_ru are never read, so they
are never computed. Same convention as host.kf.run_filter: sample 0 updates
the prior P0 without a prediction; every later sample predicts, then updates.

:func:`schedule` compresses K[k] for the gain-schedule form: piecewise
linear in k, the knots shared by the four gains and chosen greedily so that
every gain stays within its tolerance of the float64 value. On the MCU each
gain is an int64 accumulator that adds its segment's slope every sample (no
multiply, no interpolation), and the high word is the gain used. The
integers are simulated here exactly, so the compression error
|K_stored[k] - K[k]| is known for every k, not estimated.
"""

from __future__ import annotations

import functools
from array import array
from dataclasses import dataclass

import numpy as np

from .design import AxisDesign
from .qformat import QFormat, dequantize, quantize

BLOCK_NAMES = ("ra", "ua", "aa", "re", "ue", "ae", "ee")


@dataclass(frozen=True)
class GainRun:
    """K[k] (N, 4) in natural units [r, u, a, eps]; sigma[k] (N, 4) the posterior standard
    deviations; S[k] (N,) the innovation variance; max_prior/max_post (7,) the largest |P| of
    each BLOCK_NAMES entry, max_c (4,) of |P H'|, S_min/S_max."""

    K: np.ndarray
    sigma: np.ndarray
    S: np.ndarray
    max_prior: np.ndarray
    max_post: np.ndarray
    max_c: np.ndarray
    checkpoints: tuple = ()  # ((k, prior P (4, 4)), ...) at log-spaced samples


def _key(d: AxisDesign) -> tuple:
    P0 = d.P0
    return (
        d.Ts,
        d.phi,
        float(d.Q[2, 2]),
        float(d.Q[1, 2]),
        float(d.Q[0, 2]),
        float(d.Q[3, 3]),
        float(d.Q[1, 1]),
        float(d.Q[0, 1]),
        float(d.Q[0, 0]),
        d.R,
        tuple(float(P0[i, j]) for i in range(4) for j in range(4)),
    )


def gap_maxima(d: AxisDesign, g: GainRun, gap: int, recover: int) -> GainRun:
    """Largest |P| entries when a gap of ``gap`` predict-only samples starts at any checkpoint of
    ``g`` and ``recover`` updated samples follow: what skipped samples do to the ranges."""
    valid = np.r_[np.zeros(gap, dtype=bool), np.ones(recover, dtype=bool)]
    mprior = np.zeros(7)
    mpost = np.zeros(7)
    mc = np.zeros(4)
    S_max = 0.0
    kmax = np.zeros(4)
    for _, P in g.checkpoints:
        key = _key(d)[:-1] + (tuple(float(x) for row in P for x in row),)
        r = _riccati(key, gap + recover, valid)
        mprior = np.maximum(mprior, r.max_prior)
        mpost = np.maximum(mpost, r.max_post)
        mc = np.maximum(mc, r.max_c)
        S_max = max(S_max, float(r.S.max()))
        kmax = np.maximum(kmax, np.abs(r.K).max(0))
    return GainRun(kmax[None, :], np.zeros((1, 4)), np.array([S_max]), mprior, mpost, mc)


def riccati(d: AxisDesign, n: int, valid: np.ndarray | None = None) -> GainRun:
    """The Riccati recursion over n samples (valid[k] False: predict only).

    Besides the seven block entries it carries P_rr, P_uu, P_ru in float64 to
    report the posterior standard deviation of r and u; they never feed the gain.
    """
    if valid is None:
        return _riccati_cached(_key(d), int(n))
    return _riccati(_key(d), int(n), np.asarray(valid, dtype=bool))


@functools.lru_cache(maxsize=16)
def _riccati_cached(key: tuple, n: int) -> GainRun:
    return _riccati(key, n, None)


def _riccati(key: tuple, n: int, valid) -> GainRun:
    Ts, phi, qaa, qua, qra, qee, quu, qru, qrr, R, P0 = key
    h2 = Ts * Ts / 2.0
    phi2 = phi * phi
    P0 = np.array(P0).reshape(4, 4)
    prr, pru, puu = P0[0, 0], P0[0, 1], P0[1, 1]
    pra, pua, paa, pre, pue, pae, pee = P0[0, 2], P0[1, 2], P0[2, 2], P0[0, 3], P0[1, 3], P0[2, 3], P0[3, 3]
    K = np.empty((n, 4))
    sigma = np.empty((n, 4))
    S_all = np.empty(n)
    mprior = np.zeros(7)
    mpost = np.zeros(7)
    mc = np.zeros(4)
    chunk = 1 << 16
    marks = set(np.unique(np.geomspace(1, max(n - 1, 1), 40).astype(int)).tolist()) | {0}
    checkpoints = []
    for k0 in range(0, n, chunk):
        k1 = min(n, k0 + chunk)
        kf, sg, sf, pr, po = array("d"), array("d"), array("d"), array("d"), array("d")
        for k in range(k0, k1):
            if k:
                # P = F P F' + Q (r += Ts u + Ts^2/2 a, u += Ts a, eps *= phi); right side: old values
                prr, pru, puu, pra, pre, pua, pue = (
                    prr + 2 * Ts * pru + Ts * Ts * puu + 2 * h2 * pra + 2 * Ts * h2 * pua + h2 * h2 * paa + qrr,
                    pru + Ts * puu + h2 * pua + Ts * (pra + Ts * pua + h2 * paa) + qru,
                    puu + 2 * Ts * pua + Ts * Ts * paa + quu,
                    pra + Ts * pua + h2 * paa + qra,
                    phi * (pre + Ts * pue + h2 * pae),
                    pua + Ts * paa + qua,
                    phi * (pue + Ts * pae),
                )
                paa = paa + qaa
                pae = phi * pae
                pee = phi2 * pee + qee
            pr.extend((pra, pua, paa, pre, pue, pae, pee))
            if k in marks:
                checkpoints.append(
                    (k, ((prr, pru, pra, pre), (pru, puu, pua, pue), (pra, pua, paa, pae), (pre, pue, pae, pee)))
                )
            # c = P H',  S = H P H' + R,  K = c / S
            cr, cu, ca, ce = pra + pre, pua + pue, paa + pae, pae + pee
            S = ca + ce + R
            if valid is None or valid[k]:
                kr, ku, ka, ke = cr / S, cu / S, ca / S, ce / S
                # P = P - K c'
                prr -= kr * cr
                pru -= kr * cu
                puu -= ku * cu
                pra -= kr * ca
                pua -= ku * ca
                paa -= ka * ca
                pre -= kr * ce
                pue -= ku * ce
                pae -= ka * ce
                pee -= ke * ce
            else:
                kr = ku = ka = ke = 0.0
            kf.extend((kr, ku, ka, ke))
            sg.extend((prr, puu, paa, pee))
            sf.append(S)
            po.extend((pra, pua, paa, pre, pue, pae, pee))
        m = k1 - k0
        K[k0:k1] = np.frombuffer(kf).reshape(m, 4)
        sigma[k0:k1] = np.sqrt(np.maximum(np.frombuffer(sg).reshape(m, 4), 0.0))
        S_all[k0:k1] = np.frombuffer(sf)
        prior = np.abs(np.frombuffer(pr).reshape(m, 7))
        mprior = np.maximum(mprior, prior.max(0))
        mpost = np.maximum(mpost, np.abs(np.frombuffer(po).reshape(m, 7)).max(0))
        for blk in (np.frombuffer(pr).reshape(m, 7), np.frombuffer(po).reshape(m, 7)):
            # c = P H' of the prior, and of the posterior, which the C also holds
            c = np.stack(
                [blk[:, 0] + blk[:, 3], blk[:, 1] + blk[:, 4], blk[:, 2] + blk[:, 5], blk[:, 5] + blk[:, 6]], 1
            )
            mc = np.maximum(mc, np.abs(c).max(0))
    for a in (K, sigma, S_all):
        a.flags.writeable = False
    return GainRun(K, sigma, S_all, mprior, mpost, mc, tuple(checkpoints))


# --------------------------------------------------------------------------
# Gain schedule


ACC_EXTRA = 32  # accumulator fractional bits beyond the gain's own format


@dataclass(frozen=True)
class Schedule:
    """Piecewise-linear gains: segment j spans lengths[j] samples from knot j.

    Gain i is held as an int64 accumulator in Q(fmt[i].frac + ACC_EXTRA); it
    starts at start[i], adds slope[j][i] after every sample of segment j, and
    its high 32 bits (>> ACC_EXTRA) are the Q gain used. After the last
    segment the gains are held constant.
    """

    formats: tuple[QFormat, ...]  # per gain, int32
    start: tuple[int, ...]  # accumulator values at sample 0
    lengths: tuple[int, ...]
    slopes: tuple[tuple[int, ...], ...]
    stored: np.ndarray  # (N, 4) the gains the C uses, as real numbers
    error: np.ndarray  # (N, 4) |stored - float64|
    tol: tuple[float, ...]

    @property
    def n_segments(self) -> int:
        return len(self.lengths)


def _chord_ok(K: np.ndarray, k0: int, k1: int, tol: np.ndarray) -> bool:
    """Does the chord from K[k0] to K[k1] stay within tol of K on [k0, k1]?"""
    t = np.linspace(0.0, 1.0, k1 - k0 + 1)[:, None]
    chord = K[k0] + t * (K[k1] - K[k0])
    err = np.abs(chord - K[k0 : k1 + 1])
    return bool(np.all(err <= tol[k0 : k1 + 1]))


def schedule(K: np.ndarray, formats: tuple[QFormat, ...], rel_tol: float = 2e-5) -> Schedule:
    """Compress K (N, 4) into a piecewise-linear schedule; tolerance rel_tol * |K[k]| + 1 LSB."""
    n = len(K)
    lsb = np.array([f.lsb for f in formats])
    tol = rel_tol * np.abs(K) + lsb
    knots = [0]
    k0 = 0
    while k0 < n - 1:
        # grow the segment geometrically, then bisect the last step
        step = 1
        good = k0 + 1
        while good + step <= n - 1 and _chord_ok(K, k0, good + step, tol):
            good += step
            step *= 2
        while step > 1:
            step //= 2
            if good + step <= n - 1 and _chord_ok(K, k0, good + step, tol):
                good += step
        knots.append(good)
        k0 = good
    # integers: accumulator Q(frac + ACC_EXTRA); slope rounded so the sum lands near the next knot
    acc_fmts = [QFormat(64, f.frac + ACC_EXTRA) for f in formats]
    start = tuple(quantize(K[0, i], acc_fmts[i]) for i in range(4))
    lengths, slopes = [], []
    acc = list(start)
    stored = np.empty((n, 4))
    pos = 0
    for j in range(len(knots) - 1):
        L = knots[j + 1] - knots[j]
        target = [quantize(K[knots[j + 1], i], acc_fmts[i]) for i in range(4)]
        sl = tuple(int(round((target[i] - acc[i]) / L)) for i in range(4))
        for i in range(4):
            seq = np.int64(acc[i]) + np.int64(sl[i]) * np.arange(L, dtype=np.int64)
            stored[pos : pos + L, i] = np.ldexp((seq >> ACC_EXTRA).astype(np.float64), -formats[i].frac)
            acc[i] = acc[i] + sl[i] * L
        lengths.append(L)
        slopes.append(sl)
        pos += L
    for i in range(4):  # held constant from the last knot on
        stored[pos:, i] = dequantize(acc[i] >> ACC_EXTRA, formats[i])
    err = np.abs(stored - K)
    return Schedule(
        tuple(formats), start, tuple(lengths), tuple(slopes), stored, err, tuple(float(t) for t in tol.max(0))
    )


def run_gains(d: AxisDesign, z: np.ndarray, valid: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Float64 twin of a filter with a given gain sequence K[k] (natural units), host.kf conventions.

    The reference for the gain-schedule form where samples are skipped: the
    Kalman filter's gain then depends on the skips, the schedule's does not.
    Returns x_post (N, 4).
    """
    F, b = d.F, d.b
    x = np.array(d.x0, dtype=np.float64)
    out = np.empty((len(z), 4))
    for k in range(len(z)):
        if k:
            # x = F x + b
            x = F @ x + b
        if valid[k]:
            # x = x + K (z - H x)
            x = x + K[k] * (z[k] - x[2] - x[3])
        out[k] = x
    return out
