"""Float64 gain sequence of one axis and its compressed schedule.

The gain of the filter does not depend on the data, only on the design and
on which samples are skipped. :func:`riccati` runs the Riccati recursion of
DESIGN.md restricted to the seven entries of P the gain needs (P_ra, P_ua,
P_aa, P_re, P_ue, P_ae, P_ee); P_rr, P_uu and P_ru are never read, so they
are never computed. Same convention as accelnav.estimate.kf.run_filter: sample 0 updates
the prior P0 without a prediction; every later sample predicts, then updates.

:func:`schedule` compresses K[k] for the gain-schedule form: piecewise
linear in k, the knots shared by the four gains and chosen greedily so that
every gain stays within its tolerance of the float64 value. On the MCU each
gain is an int32 that adds its segment's int32 slope every sample (no
multiply, no interpolation). The
integers are simulated here exactly, so the compression error
|K_stored[k] - K[k]| is known for every k, not estimated.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import threading
from array import array
from dataclasses import dataclass

import numpy as np

from accelnav.model.design import AxisDesign
from accelnav.native.cbuild import STRICT_FLAGS
from accelnav.native.kernels import RICCATI, RICCATI_FLAGS, build, prebuilt
from accelnav.resources import package_dir

from .qformat import QFormat

BLOCK_NAMES = ("ra", "ua", "aa", "re", "ue", "ae", "ee")


KEEP = 1 << 17  # leading samples whose K, sigma, S a plan keeps (lockstep runs); beyond: summaries only


@dataclass(frozen=True)
class GainRun:
    """The Riccati recursion over n samples, summarised so that its memory does not grow with n.

    K (m, 4) in natural units [r, u, a, eps], sigma (m, 4) the posterior standard deviations and
    S (m,) the innovation variance of the first m = min(n, keep) samples; rows: the sample indices
    (sorted) whose K, sigma and S are also kept in row_K, row_sigma, row_S (the first one, log-spaced
    ones and the last, plus any asked for); kmax (4,) max |K|, sigma_max (4,), S_min, S_max over all
    n samples; max_prior/max_post (7,) the largest |P| of each BLOCK_NAMES entry, max_c (4,) of |P H'|;
    checkpoints ((k, prior P (4, 4)), ...) at log-spaced samples."""

    K: np.ndarray
    sigma: np.ndarray
    S: np.ndarray
    max_prior: np.ndarray
    max_post: np.ndarray
    max_c: np.ndarray
    checkpoints: tuple = ()
    n: int = 0
    rows: tuple = ()
    row_K: np.ndarray | None = None
    row_sigma: np.ndarray | None = None
    row_S: np.ndarray | None = None
    kmax: np.ndarray | None = None
    sigma_max: np.ndarray | None = None
    S_min: float = 0.0
    S_max: float = 0.0
    row_P: np.ndarray | None = None  # (len(rows), 16) the prior P of each row

    def at(self, k: int) -> tuple[np.ndarray, np.ndarray, float]:
        """(K, sigma, S) of sample k (negative: from the end), kept or a row."""
        k = k + self.n if k < 0 else k
        if k < len(self.K):
            return self.K[k], self.sigma[k], float(self.S[k])
        i = self.rows.index(k)  # ValueError: the sample was neither kept nor asked for
        return self.row_K[i], self.row_sigma[i], float(self.row_S[i])


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
        r = _riccati(key, gap + recover, valid, gap + recover, ())
        mprior = np.maximum(mprior, r.max_prior)
        mpost = np.maximum(mpost, r.max_post)
        mc = np.maximum(mc, r.max_c)
        S_max = max(S_max, r.S_max)
        kmax = np.maximum(kmax, r.kmax)
    return GainRun(kmax[None, :], np.zeros((1, 4)), np.array([S_max]), mprior, mpost, mc, kmax=kmax, S_max=S_max)


def riccati(d: AxisDesign, n: int, valid: np.ndarray | None = None, *, keep: int | None = None, rows=()) -> GainRun:
    """The Riccati recursion over n samples (valid[k] False: predict only), keeping the per-sample K,
    sigma, S of the first ``keep`` samples (default: all n) and of the samples in ``rows``.

    Besides the seven block entries it carries P_rr, P_uu, P_ru in float64 to
    report the posterior standard deviation of r and u; they never feed the gain.
    Memory is O(keep + len(rows)), whatever n.
    """
    n = int(n)
    keep = n if keep is None else min(int(keep), n)
    rows = tuple(sorted({int(k) for k in rows if 0 <= int(k) < n}))
    if valid is None:
        return _riccati_cached(_key(d), n, keep, rows)
    return _riccati(_key(d), n, np.asarray(valid, dtype=bool), keep, rows)


@functools.lru_cache(maxsize=16)
def _riccati_cached(key: tuple, n: int, keep: int, rows: tuple) -> GainRun:
    return _riccati(key, n, None, keep, rows)


CSRC = package_dir("accelnav.codegen") / "csrc"  # package data: riccati.c, riccati.h
# the run-time build: the strict flags plus those that decide the doubles (kernel_build.RICCATI_FLAGS)
_BUILD_FLAGS = (*STRICT_FLAGS, *(f for f in RICCATI_FLAGS if f not in STRICT_FLAGS))


def _riccati_prebuilt():
    """The kernel compiled with the package (kernel_build.py), if it was built from this very C."""
    return prebuilt(RICCATI, CSRC)


def _riccati_built():
    """The kernel built from csrc/ by the project's cffi builder; None where that cannot be done (no C
    compiler)."""
    return build(RICCATI, CSRC, _BUILD_FLAGS, "acn_riccati", required=False)


@functools.lru_cache(maxsize=1)
def _riccati_module():
    """The compiled kernel's module: the package's own build, else built on first use; None without
    either, or with ``ACCELNAV_PURE_PYTHON`` set."""
    if os.environ.get("ACCELNAV_PURE_PYTHON"):
        return None
    return _riccati_prebuilt() or _riccati_built()


def _riccati_lib():
    """(ffi, lib) of the C twin of :func:`_riccati_py` (same operations in the same order, IEEE double, no
    contraction), or None: the callers then run the Python twins."""
    mod = _riccati_module()
    return None if mod is None else (mod.ffi, mod.lib)


def bound_rows(key: tuple, n: int, bp: np.ndarray, rows) -> np.ndarray | None:
    """The C recursion of :func:`codegen.bounds.error_bound` (data-free, covariance form, all valid) at
    the sorted ``rows``; None without the C kernel (the caller then runs the Python one)."""
    lib = _riccati_lib()
    if lib is None:
        return None
    ffi, C = lib
    Ts, phi, qaa, qua, qra, qee, quu, qru, qrr, R, P0 = key
    par = np.array([Ts, phi, qaa, qua, qra, qee, quu, qru, qrr, R], dtype=np.float64)
    P0 = np.ascontiguousarray(np.array(P0, dtype=np.float64).reshape(16))
    bp = np.ascontiguousarray(bp, dtype=np.float64)
    ridx = np.ascontiguousarray(np.array(sorted(rows), dtype=np.int64))
    out = np.empty((max(1, len(ridx)), 4))

    def ptr(a, t="double *"):
        return ffi.cast(t, a.ctypes.data)

    C.acn_bound(n, ptr(par), ptr(P0), ptr(bp), len(ridx), ptr(ridx, "long *"), ptr(out))
    return out[: len(ridx)]


def bound_loop(k0: int, bp, K, dK, y, a, dw, valid, st: list) -> np.ndarray | None:
    """codegen.bounds.error_bound's recursion in C (see acn_bound_loop): (m, 4), and ``st`` (Es, Ee, Ea, Ev,
    Er, a_prev) carried to its end; None without the C kernel (the caller then runs the Python one)."""
    lib = _riccati_lib()
    if lib is None:
        return None
    ffi, C = lib
    m = len(y)
    arrs = [np.ascontiguousarray(x, dtype=np.float64) for x in (bp, K, dK, y, a, dw)]
    v = np.ascontiguousarray(valid, dtype=np.uint8)
    s = np.array(st, dtype=np.float64)
    out = np.empty((m, 4))

    def ptr(x, t="double *"):
        return ffi.cast(t, x.ctypes.data)

    C.acn_bound_loop(m, k0, *(ptr(x) for x in arrs), ptr(v, "unsigned char *"), ptr(s), ptr(out))
    st[:] = s.tolist()
    return out


def _all_rows(n: int, rows: tuple) -> tuple[list[int], list[int]]:
    """(sorted row indices: the asked-for ones, the checkpoints and the last sample; the checkpoints)."""
    marks = sorted(k for k in _marks(n) if k < n)
    return sorted(set(rows) | set(marks) | ({n - 1} if n else set())), marks


def _finish(n, keep, K, sigma, S_all, mprior, mpost, mc, rr, rowP, rowK, rowsig, rowS, ext, marks) -> GainRun:
    pos = {k: i for i, k in enumerate(rr)}
    checkpoints = tuple(
        (k, tuple(tuple(float(x) for x in rowP[pos[k]].reshape(4, 4)[r]) for r in range(4))) for k in marks
    )
    for a in (K, sigma, S_all, rowK, rowsig, rowS):
        a.flags.writeable = False
    return GainRun(
        K, sigma, S_all, mprior, mpost, mc, checkpoints, n, tuple(rr), rowK, rowsig, rowS,
        ext[:4].copy(), ext[4:8].copy(), float(ext[8]), float(ext[9]), rowP,
    )  # fmt: skip


def _riccati(key: tuple, n: int, valid, keep: int | None = None, rows: tuple = ()) -> GainRun:
    keep = n if keep is None else keep
    lib = _riccati_lib()
    if lib is None:
        return _riccati_py(key, n, valid, keep, rows)
    ffi, C = lib
    Ts, phi, qaa, qua, qra, qee, quu, qru, qrr, R, P0 = key
    par = np.array([Ts, phi, qaa, qua, qra, qee, quu, qru, qrr, R], dtype=np.float64)
    P0 = np.ascontiguousarray(np.array(P0, dtype=np.float64).reshape(16))
    rr, marks = _all_rows(n, rows)
    ridx = np.array(rr, dtype=np.int64) if rr else np.zeros(1, dtype=np.int64)
    K = np.empty((keep, 4))
    sigma = np.empty((keep, 4))
    S_all = np.empty(keep)
    mprior, mpost, mc, ext = np.empty(7), np.empty(7), np.empty(4), np.empty(10)
    m = max(1, len(rr))
    rowP, rowK, rowsig, rowS = np.empty((m, 16)), np.empty((m, 4)), np.empty((m, 4)), np.empty(m)
    v = None if valid is None else np.ascontiguousarray(valid, dtype=np.uint8)

    def ptr(a, t="double *"):
        return ffi.cast(t, a.ctypes.data)

    C.acn_riccati(
        n, ptr(par), ptr(P0), ffi.NULL if v is None else ptr(v, "unsigned char *"), keep, len(rr),
        ptr(ridx, "long *"), ptr(K), ptr(sigma), ptr(S_all), ptr(mprior), ptr(mpost), ptr(mc),
        ptr(rowP), ptr(rowK), ptr(rowsig), ptr(rowS), ptr(ext),
    )  # fmt: skip
    n_r = len(rr)
    return _finish(
        n, keep, K, sigma, S_all, mprior, mpost, mc, rr, rowP[:n_r], rowK[:n_r], rowsig[:n_r], rowS[:n_r], ext, marks
    )


def _marks(n: int) -> set:
    return set(np.unique(np.geomspace(1, max(n - 1, 1), 40).astype(int)).tolist()) | {0}


def _riccati_py(key: tuple, n: int, valid, keep: int, rows: tuple) -> GainRun:
    Ts, phi, qaa, qua, qra, qee, quu, qru, qrr, R, P0 = key
    h2 = Ts * Ts / 2.0
    phi2 = phi * phi
    P0 = np.array(P0).reshape(4, 4)
    prr, pru, puu = P0[0, 0], P0[0, 1], P0[1, 1]
    pra, pua, paa, pre, pue, pae, pee = P0[0, 2], P0[1, 2], P0[2, 2], P0[0, 3], P0[1, 3], P0[2, 3], P0[3, 3]
    K = np.empty((keep, 4))
    sigma = np.empty((keep, 4))
    S_all = np.empty(keep)
    mprior = np.zeros(7)
    mpost = np.zeros(7)
    mc = np.zeros(4)
    ext = np.zeros(10)
    ext[8] = np.inf
    rr, marks = _all_rows(n, rows)
    rset = set(rr)
    rowP, rowK, rowsig, rowS = [], [], [], []
    chunk = 1 << 16
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
            if k in rset:
                rowP.append((prr, pru, pra, pre, pru, puu, pua, pue, pra, pua, paa, pae, pre, pue, pae, pee))
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
                kr, ku, ka, ke = 0.0, 0.0, 0.0, 0.0
            kf.extend((kr, ku, ka, ke))
            sg.extend((prr, puu, paa, pee))
            sf.append(S)
            po.extend((pra, pua, paa, pre, pue, pae, pee))
        m = k1 - k0
        kc = np.frombuffer(kf).reshape(m, 4)
        sc = np.sqrt(np.maximum(np.frombuffer(sg).reshape(m, 4), 0.0))
        Sc = np.frombuffer(sf)
        if k0 < keep:
            j = min(keep, k1) - k0
            K[k0 : k0 + j], sigma[k0 : k0 + j], S_all[k0 : k0 + j] = kc[:j], sc[:j], Sc[:j]
        for k in rr:
            if k0 <= k < k1:
                rowK.append(kc[k - k0])
                rowsig.append(sc[k - k0])
                rowS.append(Sc[k - k0])
        ext[:4] = np.maximum(ext[:4], np.abs(kc).max(0))
        ext[4:8] = np.maximum(ext[4:8], sc.max(0))
        ext[8] = min(ext[8], Sc.min())
        ext[9] = max(ext[9], Sc.max())
        prior = np.abs(np.frombuffer(pr).reshape(m, 7))
        mprior = np.maximum(mprior, prior.max(0))
        mpost = np.maximum(mpost, np.abs(np.frombuffer(po).reshape(m, 7)).max(0))
        for blk in (np.frombuffer(pr).reshape(m, 7), np.frombuffer(po).reshape(m, 7)):
            # c = P H' of the prior, and of the posterior, which the C also holds
            c = np.stack(
                [blk[:, 0] + blk[:, 3], blk[:, 1] + blk[:, 4], blk[:, 2] + blk[:, 5], blk[:, 5] + blk[:, 6]], 1
            )
            mc = np.maximum(mc, np.abs(c).max(0))
    r4 = (lambda x: np.array(x, dtype=np.float64).reshape(-1, 4)) if rr else (lambda x: np.zeros((0, 4)))
    rowP_a = np.array(rowP, dtype=np.float64).reshape(-1, 16)
    return _finish(
        n, keep, K, sigma, S_all, mprior, mpost, mc, rr, rowP_a, r4(rowK), r4(rowsig), np.array(rowS, dtype=np.float64),
        ext, marks,
    )  # fmt: skip


# --------------------------------------------------------------------------
# Gain schedule


EXTRA = (0, 0, 0, 32)  # accumulator bits below each gain's LSB: K_e settles to 2e-6 of its start
HOLD = (False, False, True, False)  # gains held constant within a segment (K_a: set at its start)


@dataclass(frozen=True)
class Schedule:
    """Piecewise-linear gains on shared knots: segment j spans lengths[j] samples.

    A held gain (HOLD[i]: K_a, which settles early and then moves by a few parts in 1e6) is
    constant within a segment: slopes[j][i] is then its value over segment j, set when the segment
    starts, and start[i] is that of segment 0. Any other gain i is an accumulator of 32 + EXTRA[i]
    bits in Q(formats[i].frac + EXTRA[i]) whose high 32 bits are the gain (K_r, K_v: the int32
    itself; K_e: the high word of an int64, whose slope is far below one LSB of K_e once it
    settles). It starts at start[i] (the gain of sample 0) and adds slope[j][i] after every sample
    of segment j; after the last segment the gains are held.
    The integers are those of the C, simulated here exactly. max_error: the largest |stored - float64|
    of each gain over the declared run; head_error: that per sample over the first samples (KEEP);
    :meth:`errors` gives it for any n (replaying the table against the float64 gains).
    """

    formats: tuple[QFormat, ...]  # per gain, int32
    start: tuple[int, ...]  # accumulators at sample 0
    lengths: tuple[int, ...]
    slopes: tuple[tuple[int, ...], ...]
    max_error: np.ndarray  # (4,)
    head_error: np.ndarray  # (m, 4) |stored - float64| of the first m samples
    tol: tuple[float, ...]
    n: int = 0  # samples the schedule was built over (the declared run)
    source: object = None  # callable (k0, k1) -> float64 gains K[k0:k1] (C coordinates), for errors(n > m)
    floor: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)  # the tolerance's floor per gain, LSB of its format
    ramp: int = 0  # samples over which K_r and K_v's tolerance ramps up from 1/20

    @property
    def n_segments(self) -> int:
        return len(self.lengths)

    def gains_int(self, n: int, first: int = 0) -> np.ndarray:
        """(n - first, 4) the integers the C uses as K_r, K_v, K_a, K_e at samples first .. n-1 of an
        uninterrupted run (the high words, in the gains' formats; held after the last segment). Only the
        segments that meet first .. n - 1 are walked (the accumulators at every segment's start are
        one cumulative sum): a chunk of a long run costs its own length."""
        ex = np.array(EXTRA, dtype=np.int64)
        hold = np.array(HOLD, dtype=bool)
        out = np.empty((n - first, 4), dtype=np.int64)
        L = np.array(self.lengths, dtype=np.int64)
        S = np.array(self.slopes, dtype=np.int64).reshape(-1, 4)
        lin = np.where(hold, 0, S)
        k_at = np.concatenate([[0], np.cumsum(L)])  # segment j: samples k_at[j] .. k_at[j + 1] - 1
        # the linear accumulators at each segment's start (and after the last); held: their own values
        A_at = np.array(self.start, dtype=np.int64) + np.concatenate(
            [np.zeros((1, 4), np.int64), np.cumsum(lin * L[:, None], axis=0)]
        )
        j = max(0, int(np.searchsorted(k_at, first, side="right")) - 1)
        while j < len(L) and k_at[j] < n:
            a, b = max(int(k_at[j]), first), min(int(k_at[j + 1]), n)
            if a < b:
                t = np.arange(a - k_at[j], b - k_at[j], dtype=np.int64)[:, None]
                out[a - first : b - first] = np.where(hold, S[j], A_at[j] + lin[j] * t)
            j += 1
        if k_at[-1] < n:
            end = np.where(hold, S[-1], A_at[-1]) if len(L) else A_at[-1]
            out[max(int(k_at[-1]), first) - first :] = end
        return out >> ex

    def errors(self, n: int) -> np.ndarray:
        """(n, 4) |stored - float64| at samples 0 .. n-1 of an uninterrupted run."""
        if n <= len(self.head_error):
            return self.head_error[:n]
        lsb = np.array([f.lsb for f in self.formats])
        return np.abs(self.gains_int(n) * lsb - self.source(0, n))

    @property
    def error(self) -> np.ndarray:
        return self.errors(self.n)


def _cone(Kq: np.ndarray, tolq: np.ndarray, A: np.ndarray, hold: np.ndarray, L0: int, lo0, hi0):
    """The slopes a segment from the accumulators A may take, for the lengths L = L0 .. L0 + m - 1 given
    the samples L0 - 1 .. L0 + m - 1 of it (Kq, tolq: m + 1 rows) and the intervals (lo0, hi0) of the
    shorter lengths: (lo, hi) (m, 4), running. A linear gain's integer slope s keeps A + s t within
    tolerance at t = 1 .. L (t = 0 is A itself, the previous segment's end): s lies in the intersection of
    [(Kq[t] - tolq[t] - A) / t, (Kq[t] + tolq[t] - A) / t], a cone that narrows with t. A held gain
    (hold[i]): its value lies within tolerance at t = 0 .. L - 1. A length fits while every interval
    holds an integer."""
    t = np.arange(L0, L0 + len(Kq) - 1, dtype=np.float64)[:, None]
    d = Kq[1:] - A.astype(np.float64)
    lo = np.where(hold, Kq[:-1] - tolq[:-1], (d - tolq[1:]) / t)
    hi = np.where(hold, Kq[:-1] + tolq[:-1], (d + tolq[1:]) / t)
    lo[0] = np.maximum(lo[0], lo0)
    hi[0] = np.minimum(hi[0], hi0)
    return np.maximum.accumulate(lo, axis=0), np.minimum.accumulate(hi, axis=0)


def _longest(Kq: np.ndarray, tolq: np.ndarray, A: np.ndarray, hold: np.ndarray, L0: int, lohi: np.ndarray) -> int:
    """The longest segment (< len(Kq)) from the accumulators A, given the samples 0 .. m - 1 of it and
    ``lohi`` (8,), the intervals [lo (4), hi (4)] of the lengths below L0 that fit: L0 - 1 if L0 does
    not fit; ``lohi`` is left at the intervals of the length returned. acn_cone does the same in C."""
    lo, hi = _cone(Kq[L0 - 1 :], tolq[L0 - 1 :], A, hold, L0, lohi[:4], lohi[4:])
    ok = np.all(np.ceil(lo) <= np.floor(hi), axis=1)
    j = int(np.argmin(ok)) if not ok.all() else len(ok)
    if j:
        lohi[:4], lohi[4:] = lo[j - 1], hi[j - 1]
    return L0 - 1 + j


def _pick(lo, hi, K_end, A, L, hold) -> np.ndarray:
    """The numbers of a segment of L samples within its intervals: a linear gain, the slope whose end lands
    nearest the float64 gain K_end (sample L); a held gain, the lowest of its interval (as before the cone:
    the firmware's departure from the float64 filter after a gap is sensitive to it, measured)."""
    lo_i, hi_i = np.ceil(lo), np.floor(hi)
    want = np.where(hold, lo_i, np.floor((K_end - A) / L + 0.5))
    return np.clip(want, lo_i, hi_i).astype(np.int64)


class _Window:
    """The float64 gains of samples k0 .. k1 of an uninterrupted run, from a window of W samples that
    moves forward only (the greedy segmentation asks in increasing order): memory O(W), whatever n."""

    def __init__(self, d: AxisDesign, n: int, scale: np.ndarray, W: int):
        self.key0 = _key(d)[:-1]
        self.P = _key(d)[-1]
        self.n, self.scale, self.W = n, scale, W
        self.w0 = 0
        self.anchor = 0  # a reload starts here (the caller's current segment), at or before any request
        self.K = np.zeros((0, 4))
        self.step = max(1, W // 64)
        self.marks: dict = {}  # sample -> prior P, every `step` samples of the window (a reload starts there)

    def _load(self, k0: int) -> None:
        if k0 < self.w0:
            raise ValueError("the window only moves forward")
        if k0 > self.w0:  # the prior at k0, from the nearest prior kept at or before it
            c = max((j for j in self.marks if j <= k0), default=self.w0)
            P = self.marks.get(c, self.P)
            if c < k0:
                r = _riccati(self.key0 + (P,), k0 - c + 1, None, 0, (k0 - c,))
                P = tuple(float(x) for x in r.row_P[r.rows.index(k0 - c)])
            self.P, self.w0 = P, k0
        m = min(self.W, self.n - k0)
        r = _riccati(self.key0 + (self.P,), m, None, m, tuple(range(self.step, m, self.step)))
        self.K = np.asarray(r.K) * self.scale
        self.marks = {k0 + j: tuple(float(x) for x in r.row_P[r.rows.index(j)]) for j in range(self.step, m, self.step)}

    def __call__(self, k0: int, k1: int) -> np.ndarray:
        if k1 - k0 > self.W:  # a long replay (errors over the declared run): not through the window
            r = _riccati(self.key0 + (self.P,), k1, None, k1, ()) if k0 == self.w0 == 0 else None
            if r is None:
                raise ValueError("the window only moves forward")
            return np.asarray(r.K) * self.scale
        if k0 < self.w0 or k1 > self.w0 + len(self.K):
            self._load(min(k0, self.anchor))
        return self.K[k0 - self.w0 : k1 - self.w0]


def riccati_chunks(d: AxisDesign, n: int, chunk: int):
    """(k0, K (m, 4), S (m,)) of samples k0 .. k0 + m - 1 of an uninterrupted run of n samples, chunk
    by chunk (each from the prior at its start): memory O(chunk), whatever n."""
    key0, P = _key(d)[:-1], _key(d)[-1]
    k0 = 0
    while k0 < n:
        m = min(chunk, n - k0)
        r = _riccati(key0 + (P,), m + 1 if k0 + m < n else m, None, m, (m,) if k0 + m < n else ())
        yield k0, np.asarray(r.K), np.asarray(r.S)
        if k0 + m < n:
            P = tuple(float(x) for x in r.row_P[r.rows.index(m)])
        k0 += m


def schedule_of(
    d: AxisDesign,
    n: int,
    formats: tuple[QFormat, ...],
    rel_tol=1e-4,
    ramp: int = 0,
    window: int = 1 << 19,
    floor=0.0,
) -> Schedule:
    """:func:`schedule` of the Kalman gains of an uninterrupted run of n samples of ``d`` (C coordinates:
    K_v = Ts K_u), computed window by window: memory O(window) whatever n. Cached: codegen, its report
    and hil ask for the same schedule."""
    fl = tuple(np.broadcast_to(floor, (4,)).tolist())
    key = (_key(d), n, tuple(formats), tuple(np.broadcast_to(rel_tol, (4,)).tolist()), ramp, window, fl)
    hit = _SCHEDULES.get(key)
    if hit is None:
        scale = np.array([1.0, d.Ts, 1.0, 1.0])
        sched = schedule(_Window(d, n, scale, window), formats, rel_tol, ramp, n=n, window=window, floor=fl)
        # replays start from sample 0: a fresh source
        hit = dataclasses.replace(sched, source=_Window(d, n, scale, window))
        with _SCHEDULES_LOCK:  # the report plans its axes on threads
            _SCHEDULES[key] = hit
            while len(_SCHEDULES) > 8:
                _SCHEDULES.pop(next(iter(_SCHEDULES)))
    return hit


_SCHEDULES: dict = {}
_SCHEDULES_LOCK = threading.Lock()


# The longest segment from sample k0 (at most ``top`` samples) over which every gain keeps a whole-number
# slope within its tolerance: the cone of feasible slopes, widened over spans that double from twice the
# last segment's length (the work is a few times the segment's length). Returns (its length, the rows
# of K read in accumulator LSB, the slope intervals lohi of that length). Twice: in C and in numpy.


def _segment_c(lib, get, par, unit, A, hold8, k0: int, top: int, last: int):
    ffi, C = lib
    L0, chunk = 1, max(64, 2 * last)
    lohi = np.array([-np.inf] * 4 + [np.inf] * 4)  # the intervals of the longest length so far
    while True:
        L1 = min(top, L0 + chunk - 1)  # samples 0 .. L1 of the segment
        Kq = np.ascontiguousarray(get(k0, k0 + L1 + 1), dtype=np.float64)
        par[17] = k0
        Ad = A.astype(np.float64)
        ptr = [ffi.cast("double *", x.ctypes.data) for x in (Kq, par, Ad)]
        good = int(C.acn_cone(len(Kq), L0, *ptr, ffi.cast("unsigned char *", hold8.ctypes.data),
                              ffi.cast("double *", lohi.ctypes.data)))  # fmt: skip
        Kq = Kq[: good + 2] / unit  # the rows read below, in accumulator LSB as q_of gives them
        if good < L1 or L1 == top:
            return good, Kq, lohi
        L0, chunk = L1 + 1, 2 * chunk


def _segment_py(q, A, hold, k0: int, top: int, last: int):
    L0, chunk = 1, max(64, 2 * last)
    lohi = np.array([-np.inf] * 4 + [np.inf] * 4)
    while True:
        L1 = min(top, L0 + chunk - 1)
        Kq, tolq = q(k0, k0 + L1 + 1)
        good = _longest(Kq, tolq, A, hold, L0, lohi)
        if good < L1 or L1 == top:
            return good, Kq, lohi
        L0, chunk = L1 + 1, 2 * chunk


def _account(lib, get, k: int, m: int, A_k, sl, ex, lsb, formats, max_err, head):
    """The stored gains of samples k .. k + m - 1 (accumulators A_k + sl t; sl = 0: A_k throughout): their
    error, kept in ``head`` (its first rows) and returned as the new per-gain maximum. In C or numpy."""
    keep = len(head)
    if lib is not None:
        ffi, C = lib
        i64 = [np.ascontiguousarray(x, dtype=np.int64) for x in (A_k, sl, ex)]
        Kk = np.ascontiguousarray(get(k, k + m), dtype=np.float64)
        me = np.ascontiguousarray(max_err, dtype=np.float64)
        nh = max(0, min(keep - k, m))
        hp = ffi.cast("double *", head[k:].ctypes.data) if nh else ffi.NULL
        cs = [ffi.cast("long long *", x.ctypes.data) for x in i64]
        bad = C.acn_account(m, *cs, ffi.cast("double *", lsb.ctypes.data), ffi.cast("double *", Kk.ctypes.data),
                            ffi.cast("double *", me.ctypes.data), nh, hp)  # fmt: skip
        max_err = me
    else:
        hi = (A_k + sl * np.arange(m, dtype=np.int64)[:, None]) >> ex
        big = np.abs(hi) > 2**31 - 1
        bad = 1 + int(np.argmax(np.any(big, axis=0))) if big.any() else 0
        if not bad:
            err = np.abs(hi * lsb - get(k, k + m))
            max_err = np.maximum(max_err, err.max(0))
            if k < keep:
                head[k : min(keep, k + m)] = err[: min(keep, k + m) - k]
    if bad:
        raise ValueError(f"gain {bad - 1} leaves its int32 format {formats[bad - 1]}")
    return max_err


def schedule(
    K,
    formats: tuple[QFormat, ...],
    rel_tol=1e-4,
    ramp: int = 0,
    *,
    n: int | None = None,
    window: int = 1 << 19,
    floor=0.0,
) -> Schedule:
    """Compress the gains K (an (N, 4) array, or a callable (k0, k1) -> K[k0:k1] over n samples) into a
    piecewise-linear integer schedule.

    Tolerance per gain and sample: max(rel_tol |K[k]|, ``floor`` LSB) + half an LSB of the accumulator's
    high word (the floor of the high word adds up to one more LSB); for K_r and K_v, rel_tol ramps up
    from 1/20 over the first ``ramp`` samples. Knots are chosen greedily: from each knot the segment is
    the longest for which every gain keeps a whole-number slope (held: value) within tolerance at every
    sample, found in one pass over the narrowing interval of feasible slopes (:func:`_cone`); as the
    gains settle, the segments lengthen (at most ``window`` // 2 samples each: the span held in memory).
    """
    if callable(K):
        get = K
    else:
        Karr = np.asarray(K)
        n = len(Karr)

        def get(k0, k1):
            return Karr[k0:k1]

    ex = np.array(EXTRA, dtype=np.int64)
    lsb = np.array([f.lsb for f in formats])
    unit = lsb / 2.0**ex  # one accumulator LSB
    rel = np.broadcast_to(np.asarray(rel_tol, dtype=np.float64), (4,))
    half = np.where(ex > 0, 0.5 * 2.0**ex, 0.5)
    hold = np.array(HOLD, dtype=bool)
    floor_q = np.broadcast_to(np.asarray(floor, dtype=np.float64), (4,)) * 2.0**ex  # in accumulator LSB

    def q_of(k0, k1):
        """Kq and tolq of samples k0 .. k1 - 1."""
        Kq = get(k0, k1) / unit
        r = rel
        if ramp and k0 < ramp:  # K_r, K_v feed r and u only, whose sigma grows with time: 20x tighter at first
            w = np.clip((np.arange(k0, k1) + 1.0) / ramp, 0.05, 1.0)[:, None]
            r = rel * np.where(np.arange(4) < 2, w, 1.0)
        return Kq, np.maximum(r * np.abs(Kq), floor_q) + half

    qc = [0, np.zeros((0, 4)), np.zeros((0, 4))]  # Kq, tolq of the samples from qc[0] on, computed ahead

    def q(k0, k1):
        """q_of(k0, k1), from a block of samples computed once (the search reads a segment's samples
        again as its span widens)."""
        if k0 < qc[0] or k1 > qc[0] + len(qc[1]):
            qc[:] = [k0, *q_of(k0, min(n, max(k1, k0 + cap + 1)))]
        return qc[1][k0 - qc[0] : k1 - qc[0]], qc[2][k0 - qc[0] : k1 - qc[0]]

    keep = min(n, KEEP)
    head = np.empty((keep, 4))
    max_err = np.zeros(4)
    A = np.floor(q_of(0, 1)[0][0] + 0.5).astype(np.int64)
    A0 = A.copy()
    lengths, slopes = [], []
    k0, last = 0, 1
    cap = max(2, window // 2)

    lib = _riccati_lib()  # the search and the account in C (the same doubles), or numpy
    par = np.concatenate([unit, rel, floor_q, half, [float(ramp), 0.0]])
    hold8 = hold.astype(np.uint8)

    def account(k, m, A_k, sl):
        nonlocal max_err
        max_err = _account(lib, get, k, m, A_k, sl, ex, lsb, formats, max_err, head)

    while k0 < n - 1:
        # the cone, from the segment's start until no integer is left in it, over spans that double from
        # twice the last segment's length: the work is a few times the segment's length
        if isinstance(get, _Window):
            get.anchor = k0
        top = min(n - 1 - k0, cap)  # the longest segment: the data, and the span held in memory
        if lib is not None:
            good, Kq, lohi = _segment_c(lib, get, par, unit, A, hold8, k0, top, last)
        else:
            good, Kq, lohi = _segment_py(q, A, hold, k0, top, last)
        if good == 0:  # not even one sample (a float64 tie): the slope lands on the rounded next value
            good = 1
            sl_good = np.floor(Kq[1] + 0.5).astype(np.int64) - A
            sl_good[hold] = np.floor(Kq[0, hold] + 0.5).astype(np.int64)
        else:
            sl_good = _pick(lohi[:4], lohi[4:], Kq[good], A, good, hold)
        lin = np.where(hold, 0, sl_good)
        account(k0, good, np.where(hold, sl_good, A), lin)
        A = np.where(hold, sl_good, A + lin * good)
        lengths.append(good)
        slopes.append(tuple(int(x) for x in sl_good))
        k0 += good
        last = good
    if k0 < n:
        account(k0, n - k0, A, np.zeros(4, dtype=np.int64))
    start = np.array(slopes[0] if slopes else A, dtype=np.int64)
    start = tuple(int(x) for x in np.where(hold, start, A0))
    for sl in slopes:
        if any(abs(x) > 2**31 - 1 for x, e in zip(sl, EXTRA, strict=True) if e == 0):
            raise ValueError("a slope leaves int32")
    head.flags.writeable = False
    tolmax = rel * 1.0  # per gain: rel_tol at its widest (the absolute part is half an LSB)
    return Schedule(
        tuple(formats), start, tuple(lengths), tuple(slopes), max_err, head,
        tuple(float(x) for x in tolmax), n, get, tuple(float(x) for x in np.broadcast_to(floor, (4,))), ramp,
    )  # fmt: skip
