"""Compiled float64 filter + RTS smoother of one axis: a fast plain path and a general path.

Both return the same :class:`AxisSmooth` and agree with the reference
(:func:`accelnav.estimate.kf.run_filter` then :func:`accelnav.estimate.kf.rts_smooth`) to rounding;
tests/estimate/test_fastsmooth.py asserts 1e-9 relative, sigma-scaled, for states and
covariances. The C is csrc/fastsmooth.c, compiled when the package is built
(host/native/kernels.py); a source checkout whose C was edited since builds it on
first use with :mod:`accelnav.native.cbuild`.

General path (:func:`smooth_general`)
-------------------------------------
The 4-state filter with the acceleration update of every valid sample and any
extra scalar measurements (position fixes, zero-velocity updates), then the
4-state RTS smoother, exactly the reference's algorithm (Joseph update, the
smoother gain solved on the diagonally equilibrated prior, here by Cholesky).
An extra may carry a *gate* g > 0: it is applied only if its innovation passes
y^2 <= g S (used for automatic zero-velocity updates, see host/estimate/zupt.py);
which ones were applied is returned so the reference can be rerun with them.

Plain path (:func:`smooth_plain`): the structure of the model
-------------------------------------------------------------
With no extras, the measurement z = a + eps sees only s = (a, eps), and s is a
Markov chain of its own (F's (a, eps) block is diag(1, phi), Q has no (a, eps)
to (r, u) cross terms in the eps row). Hence:

1. The covariances and gains depend on the model and the valid mask only,
   never on z. They are computed once (:func:`plain_gains`) and cached in
   memory, keyed on the design numbers, N and the mask (and optionally on disk).
   With every sample valid, the forward part (K, C and the (a, eps) covariance
   blocks) reaches a steady state and never depends on N: it is computed once
   per design up to that state and kept on disk (:func:`steady_gains`), every
   later sample reading its last row; only the r, u rows of P, which never
   settle, are propagated per run (acn_plain_cov_steady). What is kept on disk
   is a cache entry like any (:mod:`accelnav.cachefile`): sealed with the user's
   key in blocks of rows, read (never mapped) and verified block by block, so an
   edited file is recomputed and a truncated one cannot raise SIGBUS.
2. The smoothed (a, eps) of the 4-state RTS smoother are those of the 2-state
   RTS smoother of s, because the marginal of s given all z is the 2-state
   smoothing posterior (s is Markov and z depends on s alone).
3. Smoothed r and u in closed form. Split the process noise of (r, u) as
   w_r = gr w_a + e_r, w_u = gu w_a + e_u with gr = Q_ra/Q_aa, gu = Q_ua/Q_aa
   (Ts^2/6 and Ts/2 here), so e = (e_r, e_u) is independent of w_a and of
   everything else, with covariance Qe = Q_(ru)(ru) - Q_(ru)a Q_aa^-1 Q_a(ru).
   Since w_a[k] = a[k+1] - a[k] exactly (F's a row is (0, 0, 1, 0)),

       u[k+1] = u[k] + Ts a[k] + gu (a[k+1] - a[k]) + e_u[k]
       r[k+1] = r[k] + Ts u[k] + Ts^2/2 a[k] + gr (a[k+1] - a[k]) + e_r[k].

   Taking E[. | all z] (E[e | z] = 0) gives the smoothed r, u from the
   smoothed a by this recursion without e, from E[r0, u0 | z] = (r0, u0) of the
   prior (r0, u0 are independent of every z when P0 has no (r, u)-(a, eps)
   cross terms, which the design guarantees). With Ts: the trapezoid rule for
   u and Ts^2 (a[k]/3 + a[k+1]/6) for the a part of r.
4. Smoothed covariances of r and u: the errors x~ = x - E[x | z] obey the same
   recursion with e included. For j >= k the smoothed cross-covariance of s is
   Cov(s~_k, s~_j) = C_k Cov(s~_k+1, s~_j) (C the 2-state smoother gain), so a
   linear combination of s~_0..s~_k plus independent noise has
   Cov(., s~_j) = beta' Cov(s~_k, s~_j) for every j >= k with a 2-vector beta
   that moves to k+1 as beta -> C_k' beta. Carrying beta_r, beta_u forward
   gives Cov(r~, s~) and Cov(u~, s~) at every k, and the recursion above
   gives Var(r~), Var(u~), Cov(r~, u~) (acn_plain_cov in the C, commented term
   by term). All exact: no truncation, no steady-state assumption.

The data pass is then a few multiply-adds per sample: forward means with the
cached gains, backward (a, eps) means, forward r, u. Predict-only samples
(clipped, missing) keep the gains data-independent, so the valid mask is part
of the plain path (and of the cache key).

Conventions of the outputs: those of host/estimate/kf.py. The smoother's last sample
is the filter's, exactly. Covariances are returned packed (10 numbers per
sample, upper triangle by rows: rr ru ra re uu ua ue aa ae ee); use
:func:`unpack` for (N, 4, 4).
"""

from __future__ import annotations

import hashlib
import hmac
import io
import os
import threading
import zipfile
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from accelnav.cachefile import cache_note, cached, open_entry, read_into, tag, write_entry
from accelnav.estimate.kf import Aids, Measurement
from accelnav.model.design import AxisDesign
from accelnav.native.cbuild import STRICT_FLAGS
from accelnav.native.kernels import SMOOTHER, build, prebuilt
from accelnav.resources import cache_root, package_dir

CSRC = package_dir("accelnav.estimate") / "csrc"  # package data
PACKED = ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3))
_ROWS = np.array([i for i, _ in PACKED])
_COLS = np.array([j for _, j in PACKED])
_DIAG = np.array([0, 4, 7, 9])
# packed index of each entry of a 4x4, row-major: np.take with it unpacks (N, 10) into (N, 16) in one pass, no
# fancy-index scatter
UNPACK = np.array([0, 1, 2, 3, 1, 4, 5, 6, 2, 5, 7, 8, 3, 6, 8, 9])

_lib_lock = threading.Lock()
_module = None


def _prebuilt():
    """The kernel compiled with the package (host/native/kernels.py), if it was built from this very C."""
    return prebuilt(SMOOTHER, CSRC)


def _lib():
    """The compiled kernels: the package's own build, else built on first use with the cffi builder."""
    global _module
    with _lib_lock:
        if _module is None:
            _module = _prebuilt()
        if _module is None:
            _module = build(SMOOTHER, CSRC, (*STRICT_FLAGS, "-O3"), "acn_fastsmooth")
        return _module


# --------------------------------------------------------------------------


def unpack(Pp: np.ndarray) -> np.ndarray:
    """(..., 10) packed symmetric -> (..., 4, 4)."""
    Pp = np.asarray(Pp)
    out = np.empty((*Pp.shape[:-1], 4, 4))
    out[..., _ROWS, _COLS] = Pp
    out[..., _COLS, _ROWS] = Pp
    return out


def pack(P: np.ndarray) -> np.ndarray:
    """(..., 4, 4) -> (..., 10) packed upper triangle."""
    return np.ascontiguousarray(np.asarray(P)[..., _ROWS, _COLS])


def packed_sd(Pp: np.ndarray) -> np.ndarray:
    """(..., 10) packed -> (..., 4) standard deviations of r, u, a, eps."""
    return np.sqrt(np.asarray(Pp)[..., _DIAG])


@dataclass(frozen=True)
class AxisSmooth:
    """Filter and smoother output of one axis (see the module docstring for conventions)."""

    x_prior: np.ndarray  # (N, 4) x[k|k-1]
    P_prior: np.ndarray  # (N, 10) packed
    x_post: np.ndarray  # (N, 4) x[k|k]
    P_post: np.ndarray  # (N, 10) packed
    xs: np.ndarray  # (N, 4) x[k|N-1]
    Ps: np.ndarray  # (N, 10) packed
    applied: np.ndarray  # (n_extras,) bool, in the order the extras were given
    path: str  # "plain" or "general"
    # general path: each extra's innovation y and its variance S as the filter saw them (given order; for a
    # gated-out one, at its gate): y^2 / S is the aid's NIS, without replaying the filter
    y: np.ndarray | None = None
    S: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.xs)


def _axis_struct(ffi, d: AxisDesign):
    F, Q, b = np.asarray(d.F), np.asarray(d.Q), np.asarray(d.b)
    expect = np.eye(4)
    expect[0, 1], expect[0, 2], expect[1, 2], expect[3, 3] = F[0, 1], F[0, 2], F[1, 2], F[3, 3]
    if not np.array_equal(F, expect) or np.any(b[:3] != 0) or np.any(Q[3, :3] != 0):
        raise ValueError("design: F, b or Q do not have the structure of codegen.design (see DESIGN.md)")
    if not np.array_equal(np.asarray(d.H), [[0.0, 0.0, 1.0, 1.0]]):
        raise ValueError("design: H must be [0, 0, 1, 1]")
    if not Q[2, 2] > 0:
        raise ValueError("design: Q_aa must be > 0 (sigma_n > 0)")
    m = ffi.new("acn_axis *")
    m.f01, m.f02, m.f12 = F[0, 1], F[0, 2], F[1, 2]
    m.phi, m.b_eps = F[3, 3], b[3]
    m.q = pack(Q).tolist()
    m.R = float(d.R)
    m.x0 = np.asarray(d.x0, dtype=np.float64).tolist()
    m.p0 = pack(np.asarray(d.P0, dtype=np.float64)).tolist()
    m.gr, m.gu = Q[0, 2] / Q[2, 2], Q[1, 2] / Q[2, 2]
    return m


def _design_key(d: AxisDesign) -> bytes:
    parts = [np.asarray(v, dtype=np.float64).tobytes() for v in (d.Ts, d.F, d.b, d.Q, d.H, d.R, d.x0, d.P0)]
    return b"".join(parts)


def _valid(z: np.ndarray, valid) -> np.ndarray:
    ok = np.isfinite(z)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != z.shape:
            raise ValueError(f"valid: shape {valid.shape}, expected {z.shape}")
        ok &= valid
    return ok


def _ptr(ffi, arr: np.ndarray, ctype: str):
    """A C pointer into ``arr`` (C-contiguous); the returned cdata keeps ``arr`` alive."""
    assert arr.flags.c_contiguous
    return ffi.from_buffer(ctype.replace(" *", "[]"), arr)


# --------------------------------------------------------------------------
# Plain path


@dataclass(frozen=True)
class PlainGains:
    """The data-independent part of the plain path for one (design, N, mask)."""

    key: str
    # K, Cs have N rows, or (all valid, :class:`SteadyGains`) the transient's nt rows, the last one
    # standing for every later sample (the data pass holds it)
    K: np.ndarray  # (N or nt, 4) filter gain [K_r, K_u, K_a, K_eps]; 0 on skipped samples
    Cs: np.ndarray  # (N or nt, 4) (a, eps) smoother gain C[k] = [[c00, c01], [c10, c11]]; last row 0
    P_prior: np.ndarray  # (N, 10)
    P_post: np.ndarray  # (N, 10)
    Ps: np.ndarray  # (N, 10)
    all_valid: bool
    rows: np.ndarray | None = None  # SteadyGains.rows when K, Cs are views of them (the data pass reads rows)


_CACHE: OrderedDict[str, PlainGains] = OrderedDict()
_CACHE_SIZE = 4
_cache_lock = threading.Lock()


def gain_cache_dir() -> Path | None:
    """Optional disk cache for :func:`plain_gains`: ``$ACCELNAV_GAIN_CACHE`` (off when unset). Its entries are
    sealed like every cache entry (:mod:`accelnav.cachefile`) and their arrays checked for the shapes and
    types the kernels assume before any reaches them: a folder others can write costs rebuilds, not reads
    past an array."""
    env = os.environ.get("ACCELNAV_GAIN_CACHE")
    return Path(env) if env else None


def plain_gains(
    d: AxisDesign, n: int, valid: np.ndarray | None = None, *, cache_dir: Path | None = None, steady: bool = True
) -> PlainGains:
    """Gains and covariances of the plain path for N = n samples (cached; see the module docstring).

    ``valid`` is the mask of samples whose acceleration is used (None: all).
    The key hashes every design number, n and the mask, so a model with the
    same numbers (whatever its file) shares the entry and an x0/P0 override
    does not. ``cache_dir`` (default :func:`gain_cache_dir`) also keeps them on disk.
    All valid and ``steady``: from the stored transient (:func:`steady_gains`), K and Cs then having
    its nt rows; ``steady=False`` is the full per-sample computation (the oracle of the tests).
    """
    n = int(n)
    if n < 1:
        raise ValueError("n: at least one sample is needed")
    if valid is not None:
        valid = np.ascontiguousarray(valid, dtype=bool)
        if valid.shape != (n,):
            raise ValueError(f"valid: shape {valid.shape}, expected ({n},)")
        if valid.all():
            valid = None
    h = hashlib.sha256(_design_key(d))
    h.update(n.to_bytes(8, "little"))
    h.update(b"steady" if steady else b"full")
    if valid is not None:
        h.update(np.packbits(valid).tobytes())
    key = h.hexdigest()[:24]
    with _cache_lock:
        if key in _CACHE:
            _CACHE.move_to_end(key)
            return _CACHE[key]
    cache_dir = cache_dir if cache_dir is not None else gain_cache_dir()
    if cache_dir is None:
        g = _compute_gains(d, n, valid, key, steady)
    else:
        path = Path(cache_dir) / f"gains-{key}.npz"
        g = _cached_gains(path, key, n, lambda: _compute_gains(d, n, valid, key, steady))
    with _cache_lock:
        _CACHE[key] = g
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return g


def clear_gain_cache() -> None:
    with _cache_lock:
        _CACHE.clear()


def _compute_gains(d: AxisDesign, n: int, valid: np.ndarray | None, key: str, steady: bool = True) -> PlainGains:
    _check_p0(d)
    if valid is None and steady:
        st = steady_gains(d, n)
        if st is not None:
            return _from_steady(d, n, st, key)
    mod = _lib()
    ffi, lib = mod.ffi, mod.lib
    m = _axis_struct(ffi, d)
    K = np.empty((n, 4))
    Cs = np.empty((n, 4))
    Pp, Pf, Ps = np.empty((n, 10)), np.empty((n, 10)), np.empty((n, 10))
    vmask = ffi.NULL if valid is None else _ptr(ffi, valid.view(np.uint8), "unsigned char *")
    rc = lib.acn_plain_cov(
        m, n, vmask, *(_ptr(ffi, a, "double *") for a in (K, Cs, Pp, Pf, Ps))
    )  # fmt: skip
    if rc != 0:
        raise ValueError(f"plain path: the (a, eps) prior covariance is singular at sample {-rc}")
    for a in (K, Cs, Pp, Pf, Ps):
        a.flags.writeable = False
    return PlainGains(key, K, Cs, Pp, Pf, Ps, valid is None)


def _check_p0(d: AxisDesign) -> None:
    if np.any(np.asarray(d.P0)[:2, 2:] != 0):
        raise ValueError("design: the plain path needs P0 without (r, u)-(a, eps) cross terms; use smooth_general")


def _from_steady(d: AxisDesign, n: int, st: SteadyGains, key: str) -> PlainGains:
    """An all-valid run's covariances from the stored rows (acn_plain_cov_steady); K and Cs stay the
    rows' nt entries (the data pass holds the last one for every later sample)."""
    mod = _lib()
    ffi, lib = mod.ffi, mod.lib
    Pp, Pf, Ps = np.empty((n, 10)), np.empty((n, 10)), np.empty((n, 10))
    rc = lib.acn_plain_cov_steady(
        _axis_struct(ffi, d), n, len(st.rows), _ptr(ffi, st.rows, "double *"),
        *(_ptr(ffi, a, "double *") for a in (Pp, Pf, Ps)),
    )  # fmt: skip
    if rc != 0:
        raise ValueError(f"plain path: the (a, eps) prior covariance is singular at sample {-rc}")
    for a in (Pp, Pf, Ps):
        a.flags.writeable = False
    rows = st.rows[:n]  # a run shorter than the transient a longer one settled on keeps its own rows only
    return PlainGains(key, rows[:, 0:4], rows[:, 4:8], Pp, Pf, Ps, True, st.rows)


# --------------------------------------------------------------------------
# Steady state of the all-valid plain path


@dataclass(frozen=True)
class SteadyGains:
    """The data-independent forward rows of an all-valid run (acn_plain_rows, ``SROW`` doubles per sample:
    K, C, the (a, eps) blocks of the prior and posterior covariance) up to the steady state; the last row
    stands for every later sample. None of them depends on N (the forward recursion never looks ahead)."""

    key: str
    rows: np.ndarray  # (nt, SROW)
    # False: the rows of one run too short to show the steady state (nt = its N, every row exact for it);
    # such rows are never cached, since a longer run would take their last row for a steady one
    settled: bool = True


SROW = 14  # csrc/fastsmooth.h ACN_SROW
# Steady from row nt - 1 on: over a probe at least 1.5 nt long, every later row stays within a tolerance
# (relative) of the probe's final row: STEADY_RTOL for K_a, K_eps, C and the (a, eps) blocks, GAIN_RU_RTOL
# for K_r, K_u. Those two converge far more slowly (K_r = (P_ra + P_re) / S, the difference of two
# drifting numbers near 13.5: 1e-8 off after 7.2e5 samples, 1e-12 after 9.8e5, default model) while
# they move the outputs little: cut at 1e-8 the outputs stayed within 2e-14 of the full computation
# (measured; tests/estimate/test_steady_gains.py asserts 1e-12).
STEADY_RTOL = 1e-13
GAIN_RU_RTOL = 1e-9
_PROBE0 = 1 << 17
PROBE_MAX = 1 << 21  # samples (235 MB of rows, once per design); not steady within it: per-run gains
_STEADY: OrderedDict[str, SteadyGains | None] = OrderedDict()
# the first rows of a design's steady file, read for a run shorter than its transient (unsettled): the 1e5-row
# files of a fleet each read and verified 11 MB per axis again, a fifth of their CPU (measured)
_STEADY_PART: OrderedDict[str, SteadyGains] = OrderedDict()
_STEADY_MAGIC = b"ACNSTDY2"


def steady_key(d: AxisDesign) -> str:
    """The numbers the rows depend on (F, Q, H, R, P0) and the tolerances. Not N (the transient does not
    depend on the run's length), nor x0 and b, which move only the means: a warm start shares the rows."""
    parts = [np.asarray(v, dtype=np.float64).tobytes() for v in (d.F, d.Q, d.H, d.R, d.P0)]
    h = hashlib.sha256(b"steady\0" + b"".join(parts))
    h.update(np.array([STEADY_RTOL, GAIN_RU_RTOL, SROW], dtype=np.float64).tobytes())
    return h.hexdigest()[:24]


def steady_cache_dir() -> Path:
    """Where the steady rows are kept between runs: ``accelnav.resources.cache_root()/gains``."""
    return cache_root() / "gains"


def steady_len(rows: np.ndarray) -> int | None:
    """nt (see STEADY_RTOL) of a probe's rows, or None if the probe is too short to show a steady state."""
    L = len(rows) - 1  # the last row's C is 0 (no sample after it): not a steady value
    W = rows[:L]
    fin = W[-1]
    tol = np.full(SROW, STEADY_RTOL)
    tol[:2] = GAIN_RU_RTOL
    off = np.abs(W - fin) > tol * np.abs(fin)
    bad = np.nonzero(off.any(axis=1))[0]
    nt = int(bad[-1]) + 2 if len(bad) else 1
    return nt if L - nt >= nt // 2 else None


def _plain_rows(d: AxisDesign, n: int) -> np.ndarray:
    mod = _lib()
    ffi, lib = mod.ffi, mod.lib
    rows = np.empty((n, SROW))
    rc = lib.acn_plain_rows(_axis_struct(ffi, d), n, _ptr(ffi, rows, "double *"))
    if rc != 0:
        raise ValueError(f"plain path: the (a, eps) prior covariance is singular at sample {-rc}")
    return rows


def _probe_steady(d: AxisDesign, key: str, probe_max: int) -> SteadyGains | None:
    """Rows up to the steady state, probing at most ``probe_max`` rows (doubling from _PROBE0)."""
    n = min(_PROBE0, probe_max)
    while True:
        rows = _plain_rows(d, n)
        nt = steady_len(rows)
        if nt is not None:
            rows = np.array(rows[:nt])
            rows.flags.writeable = False
            return SteadyGains(key, rows)
        if n >= probe_max:
            return None
        n = min(2 * n, probe_max)


def steady_gains(d: AxisDesign, n: int | None = None, *, cache_dir: Path | None = None) -> SteadyGains | None:
    """The steady rows of ``d`` for a run of ``n`` samples (None: any length): from memory, else from
    ``cache_dir`` (default :func:`steady_cache_dir`) if the file checks out, else computed once and written
    there atomically. A damaged or foreign file is ignored and replaced (it is a cache: never trusted).

    Never more rows than the run has: a run of n <= PROBE_MAX samples computes its n rows once; if they
    show the steady state (n >= _PROBE0 at least) it is kept as for any run, else they are returned
    unsettled (exact for this run; kept apart as a prefix that runs no longer than it read). None when
    the design does not settle within PROBE_MAX samples (per-run gains then).
    """
    key = steady_key(d)
    with _cache_lock:
        if key in _STEADY:
            _STEADY.move_to_end(key)
            return _STEADY[key]
        part = _STEADY_PART.get(key)
        if part is not None and n is not None and len(part.rows) >= n:  # a fleet of short runs: read once
            return part
    cache_dir = Path(cache_dir) if cache_dir is not None else steady_cache_dir()
    path = cache_dir / f"steady-{key}.bin"
    st = _load_steady(path, key, n)
    if st is not None and not st.settled:  # the file's first rows, enough for this run: read no more
        return _keep_part(st)  # kept (verified) for the next run no longer than they are
    if st is None and n is not None and n <= PROBE_MAX:
        n = int(n)
        prefix = cache_dir / f"prefix-{key}.bin"  # the longest unsettled run's rows: exact for any shorter one
        pre = _load_steady(prefix, key, n) if n >= _PROBE0 else None
        if pre is not None and len(pre.rows) >= n:
            return SteadyGains(key, pre.rows[:n], settled=False)
        rows = _plain_rows(d, n)
        nt = steady_len(rows) if n >= _PROBE0 else None  # a shorter run cannot show a steady state
        if nt is None:  # this run ends inside the transient: its own rows, never taken for steady ones
            rows.flags.writeable = False
            st = SteadyGains(key, rows, settled=False)
            if n >= _PROBE0:  # worth keeping: the next run of this length or less reads instead of computing
                _save_steady(prefix, st)
            # and in memory, whatever the length: a fleet of 1e5-row files computed them for every file,
            # 32 ms of each one's 80 ms of CPU (two axes, measured)
            return _keep_part(st)
        rows = np.array(rows[:nt])
        rows.flags.writeable = False
        st = SteadyGains(key, rows)
        _save_steady(path, st)
    elif st is None:
        st = _probe_steady(d, key, PROBE_MAX)
        if st is not None:
            _save_steady(path, st)
    with _cache_lock:
        _STEADY[key] = st
        while len(_STEADY) > _CACHE_SIZE:
            _STEADY.popitem(last=False)
    return st


def _keep_part(st: SteadyGains) -> SteadyGains:
    """Keep the unsettled rows ``st`` in memory for the runs no longer than they are (the longest kept per design:
    an earlier run's rows are exact for any shorter run's, tests/estimate/test_steady_gains.py)."""
    with _cache_lock:
        kept = _STEADY_PART.get(st.key)
        if kept is None or len(kept.rows) < len(st.rows):
            _STEADY_PART[st.key] = st
        _STEADY_PART.move_to_end(st.key)
        while len(_STEADY_PART) > _CACHE_SIZE:
            _STEADY_PART.popitem(last=False)
    return st


# file: header = magic (8), the key (24 ASCII), nt (int64 LE), nb (int64 LE); the header's tag (32); nb block
# tags (32 each); the rows as float64 LE. Tags are HMACs under the user's key (accelnav.cachefile.tag), bound
# to the file's name: the header's covers the header and every block tag, block i's covers its index and
# its _BLOCK_ROWS rows (the last block fewer). A run of n samples reads and verifies only the blocks holding
# its first n rows; a file that does not verify or does not fit is recomputed and overwritten, in one line.
_BLOCK_ROWS = 1 << 14  # 1.8 MB of rows: a run reads the blocks holding its rows (5 % more at most for long ones)
_STEADY_HEAD = len(_STEADY_MAGIC) + 24 + 8 + 8


def _block_tag(name: str, i: int, rows) -> bytes:
    return tag(name, b"block", i.to_bytes(8, "little"), rows)


def _load_steady(path: Path, key: str, need: int | None = None) -> SteadyGains | None:
    """The rows of a verified file, read into memory: all of them, or (``need``) at least the first ``need``
    (whole blocks), then marked unsettled (exact for runs of that length or less, never kept as the
    design's steady state). Never mapped: a file truncated under a mapping raises SIGBUS in whatever touches
    the rows next, and a cache is a file anyone may truncate (bench/speed/bench_cache_warm.py: the cost)."""
    try:
        with open_entry(path, _STEADY_HEAD + 32 * (1 + PROBE_MAX) + PROBE_MAX * SROW * 8) as (fh, size):
            head = bytearray(_STEADY_HEAD + 32)
            read_into(fh, head)
            if head[:8] != _STEADY_MAGIC:
                raise ValueError("not steady rows of this accelnav version (an older layout, or something else)")
            if head[8:32] != key.encode():
                raise ValueError("not the rows of this design")
            nt, nb = (int.from_bytes(head[i : i + 8], "little") for i in (32, 40))
            if not 1 <= nt <= PROBE_MAX or nb != -(-nt // _BLOCK_ROWS):
                raise ValueError(f"nt = {nt} rows in {nb} blocks")
            if size != _STEADY_HEAD + 32 * (1 + nb) + nt * SROW * 8:
                raise ValueError(f"{size} bytes where nt = {nt} needs {_STEADY_HEAD + 32 * (1 + nb) + nt * SROW * 8}")
            table = bytearray(32 * nb)
            read_into(fh, table)
            if not hmac.compare_digest(head[_STEADY_HEAD:], tag(path.name, head[:_STEADY_HEAD], table)):
                raise ValueError("its seal does not verify (edited, damaged, or sealed under another key)")
            blocks = nb if need is None else min(nb, -(-int(need) // _BLOCK_ROWS))
            m = min(nt, blocks * _BLOCK_ROWS)
            rows = np.empty((m, SROW), dtype="<f8")
            read_into(fh, rows)
            for i in range(blocks):
                part = rows[i * _BLOCK_ROWS : (i + 1) * _BLOCK_ROWS]
                if not hmac.compare_digest(table[32 * i : 32 * (i + 1)], _block_tag(path.name, i, part)):
                    raise ValueError(f"rows block {i} does not verify (edited, damaged, or sealed under another key)")
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        cache_note(path, getattr(exc, "strerror", None) or str(exc))
        return None
    rows.flags.writeable = False
    return SteadyGains(key, rows, settled=m == nt)


def _save_steady(path: Path, st: SteadyGains) -> None:
    """Best effort: a cache that cannot be written (read-only home, full disk) costs only time."""
    rows = np.ascontiguousarray(st.rows, dtype="<f8")
    nt = len(rows)
    nb = -(-nt // _BLOCK_ROWS)
    head = _STEADY_MAGIC + st.key.encode() + nt.to_bytes(8, "little") + nb.to_bytes(8, "little")
    table = b"".join(_block_tag(path.name, i, rows[i * _BLOCK_ROWS : (i + 1) * _BLOCK_ROWS]) for i in range(nb))
    write_entry(path, head, tag(path.name, head, table), table, memoryview(rows).cast("B"))


def clear_steady_cache() -> None:
    """Forget the steady rows held in memory (the files stay)."""
    with _cache_lock:
        _STEADY.clear()
        _STEADY_PART.clear()


_GAIN_NAMES = ("K", "Cs", "P_prior", "P_post", "Ps")


def _cached_gains(path: Path, key: str, n: int, compute) -> PlainGains:
    """``compute()``'s gains through the sealed entry at ``path`` (``$ACCELNAV_GAIN_CACHE``): read back only
    if it verifies and every array has the shape and type the C kernels will assume for ``n`` samples."""
    made: list[PlainGains] = []

    def build() -> bytes:
        made.append(compute())
        buf = io.BytesIO()
        g = made[0]
        np.savez(buf, **{k: getattr(g, k) for k in _GAIN_NAMES}, all_valid=np.bool_(g.all_valid))
        return buf.getvalue()

    limit = (2 * 4 + 3 * 10) * 8 * n + (1 << 16)  # the arrays of n samples and the zip's headers
    data = cached(path, build, limit=limit, check=lambda b: _gains_from(b, key, n))
    return made[0] if made else _gains_from(data, key, n)


def _gains_from(data, key: str, n: int) -> PlainGains:
    """The gains of a cached entry, refused (ValueError) unless each array is what the kernels read: K and
    Cs (m, 4) float64 with m = n (or 1 <= m <= n, all valid: the steady transient), P (n, 10) float64."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as f:
            if sorted(f.files) != sorted((*_GAIN_NAMES, "all_valid")):
                raise ValueError(f"arrays {', '.join(f.files)}")
            arrays = {k: f[k] for k in _GAIN_NAMES}
            all_valid = f["all_valid"]
    except (OSError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"not the gains' NPZ ({exc})") from None
    if all_valid.shape != () or all_valid.dtype != np.bool_:
        raise ValueError("all_valid: not one bool")
    m = len(arrays["K"]) if arrays["K"].ndim else 0
    for k, a in arrays.items():
        want = (m, 4) if k in ("K", "Cs") else (n, 10)
        if a.dtype != np.float64 or a.shape != want or not a.flags.c_contiguous:
            said = "(rows, 4)" if k in ("K", "Cs") else str(want)
            raise ValueError(f"{k}: {a.dtype} {a.shape}, expected C-ordered float64 {said}")
    if not (m == n or (bool(all_valid) and 1 <= m <= n)):
        raise ValueError(f"K: {m} rows for {n} samples")
    for a in arrays.values():
        a.flags.writeable = False
    return PlainGains(key, *arrays.values(), bool(all_valid))


def plain_data(d: AxisDesign, z: np.ndarray, valid: np.ndarray | None, g: PlainGains, *, out=None):
    """The data pass alone: (x_post, xs), each (N, 4). ``out`` may pass two preallocated arrays.

    ``valid`` must be the mask ``g`` was computed for (None when all valid);
    this is what the benchmark times.
    """
    mod = _lib()
    ffi, lib = mod.ffi, mod.lib
    z = np.ascontiguousarray(z, dtype=np.float64)
    n = len(z)
    xf, xs = out if out is not None else (np.empty((n, 4)), np.empty((n, 4)))
    vbytes = None if valid is None else np.ascontiguousarray(valid, dtype=bool).view(np.uint8)
    vmask = ffi.NULL if vbytes is None else _ptr(ffi, vbytes, "unsigned char *")
    if g.rows is not None:  # K, Cs are columns 0..3 and 4..7 of the steady rows
        rows = _ptr(ffi, g.rows, "double *")
        K, Cs, stride = rows, rows + 4, SROW
    else:
        K, Cs, stride = _ptr(ffi, g.K, "double *"), _ptr(ffi, g.Cs, "double *"), 4
    lib.acn_plain_data(
        _axis_struct(ffi, d),
        n,
        _ptr(ffi, z, "double *"),
        vmask,
        K,
        Cs,
        stride,
        len(g.K),
        _ptr(ffi, xf, "double *"),
        _ptr(ffi, xs, "double *"),
    )
    return xf, xs


def _priors(d: AxisDesign, x_post: np.ndarray) -> np.ndarray:
    x_prior = np.empty_like(x_post)
    x_prior[0] = d.x0
    x_prior[1:] = x_post[:-1] @ np.asarray(d.F).T + np.asarray(d.b)
    return x_prior


def smooth_plain(d: AxisDesign, z: np.ndarray, *, valid: np.ndarray | None = None) -> AxisSmooth:
    """Filter and smoother without extra measurements (the fast path)."""
    z = np.asarray(z, dtype=np.float64)
    ok = _valid(z, valid)
    mask = None if ok.all() else ok
    g = plain_gains(d, len(z), mask)
    zc = np.where(ok, z, 0.0)
    xf, xs = plain_data(d, zc, mask, g)
    return AxisSmooth(_priors(d, xf), g.P_prior, xf, g.P_post, xs, g.Ps, np.zeros(0, dtype=bool), "plain")


# --------------------------------------------------------------------------
# General path


@dataclass(frozen=True)
class Extras:
    """Extra scalar measurements as arrays, stably sorted by sample: made once by :meth:`of` and passed
    to :func:`smooth_general` many times (a likelihood search filters the same extras hundreds of times,
    and turning the Measurement objects into arrays cost as much as the filter itself)."""

    k: np.ndarray  # (n,) int64, ascending
    h: np.ndarray  # (n, 4)
    z: np.ndarray  # (n,)
    R: np.ndarray  # (n,) > 0
    order: np.ndarray  # position i of the sorted arrays holds the given measurement order[i]

    @classmethod
    def of(cls, extras: Sequence[Measurement] | Aids | Extras) -> Extras:
        """Sorted arrays of ``extras``; :class:`accelnav.estimate.kf.Aids` go through as arrays (a long run's
        rests are 1e6 zero-velocity updates and more: no object per update)."""
        if isinstance(extras, Extras):
            return extras
        if isinstance(extras, Aids):
            if len(extras) and not np.all(extras.R > 0):
                raise ValueError(f"extra measurement at sample {int(extras.k[~(extras.R > 0)][0])} has variance <= 0")
            k = extras.k  # rests' updates come sorted: no sort of 1e6 and more of them then, and no copy
            c = np.ascontiguousarray
            if np.all(k[1:] >= k[:-1]):
                return cls(c(extras.k), c(extras.h), c(extras.z), c(extras.R), np.arange(len(k)))
            order = np.argsort(k, kind="stable")
            return cls(c(extras.k[order]), c(extras.h[order]), c(extras.z[order]), c(extras.R[order]), order)
        ne = len(extras)
        ek = np.array([m.k for m in extras], dtype=np.int64).reshape(ne)
        eR = np.array([m.R for m in extras], dtype=np.float64).reshape(ne)
        if ne and not np.all(eR > 0):
            raise ValueError(f"extra measurement at sample {int(ek[~(eR > 0)][0])} has variance <= 0")
        order = np.argsort(ek, kind="stable")
        eh = np.array([m.h for m in extras], dtype=np.float64).reshape(ne, 4)[order]
        ez = np.array([m.z for m in extras], dtype=np.float64).reshape(ne)[order]
        c = np.ascontiguousarray
        return cls(c(ek[order]), c(eh), c(ez), c(eR[order]), order)

    def __len__(self) -> int:
        return len(self.k)


def smooth_general(
    d: AxisDesign,
    z: np.ndarray,
    *,
    valid: np.ndarray | None = None,
    extras: Sequence[Measurement] | Extras = (),
    gates: Sequence[float] | None = None,
    out: AxisSmooth | None = None,
) -> AxisSmooth:
    """Filter and smoother with extra scalar measurements (see accelnav.estimate.kf.position_fix, zero_velocity).

    ``gates[i]`` > 0 makes extra i conditional (applied iff y^2 <= gates[i] S);
    0 or None applies it unconditionally. ``applied`` in the result follows
    the order of ``extras``. ``out``, a previous result of the same length,
    is overwritten instead of allocating (a long-running caller avoids the
    page faults of fresh 300 MB buffers at N = 1e6).
    """
    mod = _lib()
    ffi, lib = mod.ffi, mod.lib
    z = np.asarray(z, dtype=np.float64)
    n = len(z)
    if n < 1:
        raise ValueError("z: at least one sample is needed")
    ok = _valid(z, valid)
    zc = np.ascontiguousarray(np.where(ok, z, 0.0))
    ex = Extras.of(extras)
    ne = len(ex)
    if ne and (ex.k[0] < 0 or ex.k[-1] >= n):
        bad = int(ex.k[(ex.k < 0) | (ex.k >= n)][0])
        raise ValueError(f"extra measurement at sample {bad} is outside 0..{n - 1}")
    order = ex.order
    eks, eh, ez, eR = ex.k, ex.h, ex.z, ex.R
    eg = np.zeros(ne) if gates is None else np.asarray(gates, dtype=np.float64).reshape(ne)
    eg = np.ascontiguousarray(eg[order])
    applied = np.zeros(max(ne, 1), dtype=np.uint8)
    ey, eS = np.zeros(max(ne, 1)), np.zeros(max(ne, 1))
    if out is not None and len(out) == n and out.path == "general":
        xp, Pp, xf, Pf, xs, Ps = out.x_prior, out.P_prior, out.x_post, out.P_post, out.xs, out.Ps
    else:
        xp, xf, xs = np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 4))
        Pp, Pf, Ps = np.empty((n, 10)), np.empty((n, 10)), np.empty((n, 10))
    keep = [eks, eh, ez, eR, eg]  # keep the buffers alive across the call
    rc = lib.acn_general(
        _axis_struct(ffi, d),
        n,
        _ptr(ffi, zc, "double *"),
        _ptr(ffi, ok.view(np.uint8), "unsigned char *"),
        ne,
        ffi.from_buffer("long[]", eks) if ne else ffi.NULL,
        *((_ptr(ffi, a, "double *") if ne else ffi.NULL) for a in keep[1:]),
        _ptr(ffi, applied, "unsigned char *"),
        *(_ptr(ffi, a, "double *") for a in (ey, eS, xp, Pp, xf, Pf, xs, Ps)),
    )
    if rc != 0:
        raise ValueError(f"general path: the prior covariance is not positive definite at sample {-rc}")
    done = np.zeros(ne, dtype=bool)
    done[order] = applied[:ne].astype(bool)
    y, S = np.empty(ne), np.empty(ne)
    y[order], S[order] = ey[:ne], eS[:ne]
    return AxisSmooth(xp, Pp, xf, Pf, xs, Ps, done, "general", y, S)


def smooth(
    d: AxisDesign,
    z: np.ndarray,
    *,
    valid: np.ndarray | None = None,
    extras: Sequence[Measurement] = (),
    gates: Sequence[float] | None = None,
) -> AxisSmooth:
    """The plain path when there are no extras (and P0 allows it), else the general path."""
    P0 = np.asarray(d.P0)
    if not extras and not np.any(P0[:2, 2:] != 0):
        return smooth_plain(d, z, valid=valid)
    return smooth_general(d, z, valid=valid, extras=extras, gates=gates)
