"""Noise figures (sigma_n, sigma_eps, R) from motion recordings by maximum likelihood of the innovations.

Likelihood
----------
For a linear-Gaussian state-space model the log-likelihood of all measurements is the sum over every scalar
update of log N(y; 0, S), y the innovation and S its variance (prediction-error decomposition). At sample k
the filter applies the acceleration z[k] (innovation y = z - (a + eps) of the prior, S = P_aa + 2 P_ae + P_ee
+ R) and then each extra measurement of that sample (zero-velocity update, position fix), in order
(:mod:`accelnav.estimate.kf` conventions). The compiled filter (:mod:`accelnav.estimate.fastsmooth`) gives
the priors of every sample; the acceleration terms are then one vectorised expression, and the extras' terms
are replayed from the prior of their sample (the acceleration update first), a few per rest or fix.

Without extras, z = a + eps + v sees the sum of two random walks (a with sigma_n, the bias with sigma_eps) and
white noise: sigma_n and R are identified, sigma_eps hardly (it is a small part of the low-frequency power).
Rests (zero-velocity updates: u = 0) and position fixes tie the double integral of a down and so separate
the bias from the motion: they are what identifies sigma_eps.

Estimate
--------
theta = (ln sigma_n, ln sigma_eps, ln R), or a subset (the others kept), optionally with each axis's
constant bias c2 (searched in units of 0.01 m/s^2; it sets the filter's prior bias and the level the bias
reverts to), maximised by Nelder-Mead from the starting model's values.

Intervals
---------
Noise figures: 95 % profile-likelihood intervals in ln(figure): the values of ln(figure) at which the
profile -ln L (minimised over the other tuned figures) rises 1.92 (chi-square, 1 dof, 3.84 / 2) above its
minimum. The bias walk is weakly observable, so -ln L is far from quadratic in ln sigma_eps and an interval
from the curvature at the optimum (``se_ln``, kept for reference: the observed information, the
central-difference Hessian of -ln L in theta) covers the truth too rarely. Each end is found by following
the signed root r = sqrt(2 (profile - min)), nearly linear in ln(figure), from the Wald guess, with the
other figures re-optimised at every step (Nelder-Mead, started from the Hessian's linear prediction or the
previous step's optimum, whichever fits better). An end that is not reached inside the search range
(:func:`figure_bounds`) is open: the figure is then reported as not identified by the data, as it is when its
interval spans more than a factor e^(2 x 1.96 x ``NOT_IDENTIFIED_SE``) ~ 50, or when the evaluation budget
ran out before an end closed (said as such).
c2 keeps the normal interval from the observed information (the innovations are linear in c2).

Budget: ``max_evaluations`` likelihood evaluations in all; the search takes at most a third, the
Hessian a few, the profiles the rest, best-determined figure (smallest se_ln) first, each end of each
profile at most an equal share of what is left when it starts: the weakest figure, last, gets what the
others did not need, and a profile that wanders to its search bound cannot starve the others.

The result is adopted only if it is significantly better than the starting model: the likelihood-ratio
statistic 2 (ln L(theta_hat) - ln L(theta_0)) must exceed the chi-square 95 % point with as many degrees of
freedom as figures tuned. A well-specified starting model is thus kept (in about 95 % of runs), rather than
replaced by the noise of its estimate.

Zero-velocity updates found automatically are gated once, with the starting model, and the applied set is then
held fixed, so the likelihood is a smooth function of theta.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from accelnav.estimate import fastsmooth
from accelnav.estimate.chunked import GROW, checked_piece
from accelnav.estimate.kf import Measurement, batch_update
from accelnav.lazy import lazy_module
from accelnav.model.design import axis_design
from accelnav.model.edit import revalidate, with_noise
from accelnav.model.load import Model
from accelnav.progress import note

optimize = lazy_module("scipy.optimize")
stats = lazy_module("scipy.stats")

FIGURES = ("sigma_n", "sigma_eps", "R")
NOT_IDENTIFIED_SE = 1.0  # se of ln(figure): a 95 % interval wider than a factor e^(2 x 1.96) ~ 50
MAX_EVALUATIONS = 1500  # search (at most a third), Hessian and profile intervals together
# 1.92: the rise of -ln L at a 95 % profile interval end, chi2(1 dof).ppf(0.95) / 2 = z(0.975)^2 / 2
PROFILE_DROP = 0.5 * NormalDist().inv_cdf(0.975) ** 2
R95 = math.sqrt(2.0 * PROFILE_DROP)  # 1.96: the signed root at an end
LN_BOUNDS = {"sigma_n": (1e-4, 1e3), "sigma_eps": (1e-9, 10.0), "R": (1e-10, 1e4)}
# R at least a tenth of what the datasheet's noise and the read-out's rounding give (3x quieter: not credible;
# the rounding is not white where the analog noise is below a step, and the motion's model takes some of it)
NOISE_FLOOR_SHARE = 0.1


def figure_bounds(model: Model) -> dict[str, tuple[float, float, str, str]]:
    """(low, high, why low, why high) of each noise figure's search range, tied to the sensor where it can be.

    R: from NOISE_FLOOR_SHARE of the datasheet's analog noise power plus the read-out's rounding (step^2 / 12),
    to the full scale squared; below the floor the filter would take every sample as exact and explain the
    motion's jolts by a huge sigma_n (a foot's heel strikes drove R to the search limit and sigma_n to 26-63).
    sigma_n: up to the full scale per sqrt(s), an acceleration that wanders over the sensor's whole range within
    a second (1 sd); beyond it, the motion is no random walk the model can describe. sigma_eps: LN_BOUNDS.
    A bound the starting model lies outside is moved to it (the user's model is the user's call)."""
    from accelnav.model.design import steps_and_noise

    steps, noise = steps_and_noise(model)
    floor = NOISE_FLOOR_SHARE * (float(np.max(steps)) ** 2 / 12.0 + noise**2)
    full = model.max_accel_m_s2
    out = {
        "sigma_n": (LN_BOUNDS["sigma_n"][0], full, "the search limit", "the sensor's full scale per sqrt(s)"),
        "sigma_eps": (*LN_BOUNDS["sigma_eps"], "the search limit", "the search limit"),
        "R": (max(floor, LN_BOUNDS["R"][0]), full**2, "the sensor's rounding and datasheet noise floor",
              "the full scale squared"),
    }  # fmt: skip
    for f, (lo, hi, wl, wh) in out.items():
        v = float(getattr(model.noise, f))
        if v > 0:
            out[f] = (min(lo, v), max(hi, v), wl, wh)
    return out


@dataclass(frozen=True)
class RunData:
    """The run a likelihood reads, a chunk at a time: ``n`` samples of ``n_axes`` axes, rows s..e read by
    ``read(s, e)`` -> (t, accel (m, n_axes), clipped (m, n_axes) bool) in pieces of ``chunk`` samples, and each
    axis's aids: :class:`fastsmooth.Extras` held whole, or ``chunked.ChunkAids`` made for each chunk alone (a long
    run's rests are millions of updates), or None. The whole run in memory is one chunk (:meth:`of`)."""

    n: int
    n_axes: int
    read: Callable
    aids: Sequence
    chunk: int
    scratch: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)  # buffers, kept between passes

    def buffers(self, j: int) -> list[np.ndarray]:
        """Axis j's chunk buffers, allocated once for every evaluation (fresh pages on every pass cost time)."""
        if j not in self.scratch:
            size = min(self.chunk, self.n)
            self.scratch[j] = [np.empty((size, w)) for w in (GROW, 4, 4, 4, 10)]
        return self.scratch[j]

    @classmethod
    def of(cls, accel: np.ndarray, valid: np.ndarray, extras, chunk: int | None = None) -> RunData:
        """Arrays in memory, one chunk unless ``chunk`` says otherwise."""
        n, m = accel.shape
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != accel.shape:
            raise ValueError(f"valid: shape {valid.shape}, expected {accel.shape}")
        aids = [fastsmooth.Extras.of(e) for e in extras]  # once: the search filters them hundreds of times
        for ex in aids:
            if len(ex) and (ex.k[0] < 0 or ex.k[-1] >= n):
                bad = int(ex.k[(ex.k < 0) | (ex.k >= n)][0])
                raise ValueError(f"extra measurement at sample {bad} is outside 0..{n - 1}")
        return cls(n, m, lambda s, e: (None, accel[s:e], ~valid[s:e]), aids, max(1, n if chunk is None else chunk))

    @property
    def count(self) -> int:
        """Aids over every axis."""
        return sum(_aid_count(a) for a in self.aids)


def _aid_count(aid) -> int:
    return 0 if aid is None else len(aid) if isinstance(aid, fastsmooth.Extras) else int(aid.count)


def _piece(aid, j: int, s: int, e: int) -> fastsmooth.Extras | None:
    """Axis j's aids of samples s..e-1 (sample numbers of the run), in the filter's order; a ChunkAids' piece checked
    as the smoothing passes check it (a caller's own may give anything)."""
    if aid is None or not _aid_count(aid):
        return None
    if isinstance(aid, fastsmooth.Extras):
        a, b = int(np.searchsorted(aid.k, s)), int(np.searchsorted(aid.k, e))
        return fastsmooth.Extras(aid.k[a:b], aid.h[a:b], aid.z[a:b], aid.R[a:b], aid.order[a:b])
    piece = aid.between(s, e)
    checked_piece(piece, j, s, e)
    return None if piece is None else piece.ex


# bytes per sample and axis a chunk of the likelihood holds: acn_chunkg_fwd's store row, its four outputs (filter
# means and sds, prior means and packed covariances), the input's z and its flags, and the terms' temporaries
SAMPLE_BYTES = 8 * (GROW + 4 + 4 + 4 + 10) + 8 * 8 + 2


def chunk_samples(n_axes: int, budget: int) -> int:
    """Samples per chunk of the likelihood so that its buffers fit ``budget`` bytes (2 at least)."""
    return max(2, int(budget) // (n_axes * SAMPLE_BYTES + 8))


class _Pass:
    """The filter's forward pass over one axis, chunk by chunk (acn_chunkg_fwd, the same steps as acn_general's
    forward half: the priors of every sample, bit for bit): the prior carried between chunks, the buffers
    reused for every chunk."""

    def __init__(self, d, buffers: list[np.ndarray]) -> None:
        mod = fastsmooth._lib()
        self.ffi, self.lib, self.d = mod.ffi, mod.lib, d
        self.m = fastsmooth._axis_struct(self.ffi, d)
        self.carry = np.concatenate([np.asarray(d.x0, dtype=np.float64), fastsmooth.pack(np.asarray(d.P0, float))])
        # acn_chunkg_fwd's store rows (scratch here), filter means and sds, prior means and packed covariances
        self.store, self.xf, self.sdf, self.xp, self.Pp = buffers

    def priors(self, zc: np.ndarray, ok: np.ndarray, ex: fastsmooth.Extras | None, s: int, last: bool):
        """The (m, 4) prior means and (m, 10) packed prior covariances of samples s..s+m-1."""
        m, ne = len(zc), 0 if ex is None else len(ex)
        p, ffi = (lambda a, c="double *": fastsmooth._ptr(self.ffi, a, c)), self.ffi
        ek = np.ascontiguousarray(ex.k - s, dtype=np.int64) if ne else np.zeros(1, dtype=np.int64)
        arrs = [ex.h, ex.z, ex.R, np.zeros(ne)] if ne else [np.zeros(4)] * 4
        arrs = [np.ascontiguousarray(a, dtype=np.float64) for a in arrs]
        applied = np.zeros(max(ne, 1), dtype=np.uint8)
        # NULL for the filter's means and sds: nothing here reads them, so the kernel makes none
        self.lib.acn_chunkg_fwd(
            self.m, m, int(last), p(zc), p(ok.view(np.uint8), "unsigned char *"), ne, ffi.from_buffer("long[]", ek),
            *(p(a) for a in arrs), p(applied, "unsigned char *"), p(self.carry), p(self.store), ffi.NULL,
            ffi.NULL, p(self.xp), p(self.Pp), ffi.NULL, ffi.NULL,
        )  # fmt: skip
        return self.xp[:m], self.Pp[:m]


def data_loglik(model: Model, data: RunData, after_chunk: Callable[[int], None] | None = None) -> float:
    """ln L of ``data`` under ``model``: the filter's pass over every chunk, each axis's terms summed chunk by
    chunk (one chunk: the very sums of a whole-array pass). ``after_chunk(samples done)`` is called after each
    chunk (a time bound stops an evaluation there)."""
    n, size = data.n, min(data.chunk, data.n)
    passes = [_Pass(axis_design(model, j), data.buffers(j)) for j in range(data.n_axes)]
    ll = [0.0] * data.n_axes
    for s in range(0, n, size):
        e = min(s + size, n)
        _, accel, clipped = data.read(s, e)
        for j, ps in enumerate(passes):
            z = np.asarray(accel[:, j], dtype=np.float64)
            ok = ~np.asarray(clipped[:, j], dtype=bool) & np.isfinite(z)
            ex = _piece(data.aids[j], j, s, e)
            xp, Pa = ps.priors(np.ascontiguousarray(np.where(ok, z, 0.0)), ok, ex, s, e == n)
            with np.errstate(invalid="ignore", divide="ignore"):
                ll[j] += _chunk_loglik(ps.d, z, ok, xp, Pa, ex, s)
        if after_chunk is not None:
            after_chunk(e)
    total = sum(ll)
    if not math.isfinite(total):  # an innovation variance <= 0: a covariance that is not positive definite
        raise ValueError("the likelihood is not finite: a prior covariance is not positive definite")
    return total


def _chunk_loglik(d, z: np.ndarray, ok: np.ndarray, xp: np.ndarray, Pa: np.ndarray, ex, s: int) -> float:
    """One axis's terms of samples s..s+m-1 from their priors ``xp``, ``Pa`` (packed) and their aids ``ex``."""
    pk = fastsmooth.PACKED.index
    # only the (a, eps) block enters S, only the extras' samples are unpacked
    S = Pa[:, pk((2, 2))] + 2.0 * Pa[:, pk((2, 3))] + Pa[:, pk((3, 3))] + d.R
    y = z - (xp[:, 2] + xp[:, 3])
    if not ok.all():  # every sample valid (the common case): no copies of S and y
        S, y = S[ok], y[ok]
    # log(2 pi S) + y^2 / S, in place: the same doubles, summed in the same order, as the expression written out
    y *= y
    y /= S
    S *= 2.0 * math.pi
    np.log(S, out=S)
    S += y
    ll = -0.5 * float(np.sum(S))
    if ex is None or not len(ex):
        return ll
    # the extras' terms, replayed from the prior of their sample (acceleration update first, then the extras in
    # order): every sample's replay is independent of the others', so all samples are replayed at once
    ks, hs, zs, rs = ex.k - s, ex.h, ex.z, ex.R
    uk, first, group = np.unique(ks, return_index=True, return_inverse=True)
    rank = np.arange(len(ks)) - first[group]
    X = xp[uk].copy()
    P = fastsmooth.unpack(Pa[uk])
    zk = ok[uk]
    h_z = np.broadcast_to(np.array([0.0, 0.0, 1.0, 1.0]), (int(zk.sum()), 4))
    X[zk], P[zk], _ = _update_many(X[zk], P[zk], h_z, z[uk][zk], np.full(int(zk.sum()), d.R))
    for r in range(int(rank.max()) + 1):
        sel = rank == r
        g = group[sel]
        X[g], P[g], terms = _update_many(X[g], P[g], hs[sel], zs[sel], rs[sel])
        ll -= 0.5 * float(np.sum(terms))
    return ll


def _update_many(X, P, H, z, R):
    """Scalar updates of many (x, P) at once: (x, P, log(2 pi S) + y^2 / S) per row."""
    X, P, y, S = batch_update(X, P, H, z, R)
    return X, P, np.log(2.0 * math.pi * S) + y * y / S


def loglik(
    model: Model,
    accel: np.ndarray,
    valid: np.ndarray,
    extras: Sequence[Sequence[Measurement] | fastsmooth.Extras],
) -> float:
    """ln L of the accelerations (N, axes) and each axis's extra measurements under ``model``."""
    return data_loglik(model, RunData.of(np.asarray(accel, dtype=np.float64), valid, extras))


C2_SCALE = 0.01  # m/s^2 per unit of the search variable for c2 (the noise figures are searched as logarithms)


def _is_c2(name: str) -> bool:
    return name.startswith("c2.")


@dataclass(frozen=True)
class TuneResult:
    figures: tuple[str, ...]  # tuned: noise figures and "c2.<axis>"
    start: dict[str, float]  # every figure, tuned or not
    estimate: dict[str, float]
    se_ln: dict[str, float]  # noise figures: standard error of ln(figure); c2: standard error in m/s^2
    ci95: dict[str, tuple[float, float]]
    ll_start: float
    ll_estimate: float
    lr: float  # 2 (ll_estimate - ll_start)
    p_value: float  # of lr under the starting model (chi-square, len(figures) dof)
    adopted: bool
    evaluations: int
    converged: bool
    at_bound: tuple[str, ...] = ()  # figures whose estimate sits on the search bound
    # each noise figure's search range: (low, high, why low, why high), figure_bounds
    bounds: dict[str, tuple[float, float, str, str]] = dataclasses.field(default_factory=dict)
    # noise figures: how each end of the profile interval ended: "closed", "open" (the profile does not rise
    # 1.92 inside the search range: that end is the search bound) or "budget" (evaluations ran out: nan)
    ends: dict[str, tuple[str, str]] = dataclasses.field(default_factory=dict)

    def identified(self, name: str) -> bool:
        return not self.why_not_identified(name)

    def why_not_identified(self, name: str) -> str:
        """'' when ``name`` is identified by the data; else the reason, in a few words."""
        if name in self.at_bound:
            return self.bound_said(name)
        s = self.se_ln[name]
        if _is_c2(name):
            ok = math.isfinite(s) and s <= NOT_IDENTIFIED_SE * C2_SCALE * 10  # c2 known to 0.1 m/s^2 (10 mg)
            return "" if ok else "interval too wide"
        ends = self.ends.get(name, ("closed", "closed"))
        if "open" in ends:
            side = " and ".join(w for w, e in zip(("below", "above"), ends, strict=True) if e == "open")
            return f"profile open {side} within the search range"
        if "budget" in ends:
            return "profile not closed within the evaluation budget"
        lo, hi = self.ci95[name]
        if not (lo > 0 and hi / lo <= math.exp(2 * 1.96 * NOT_IDENTIFIED_SE)):
            return "interval too wide"
        return ""

    def bound_said(self, name: str) -> str:
        """'at its lower bound (why, value)' for a figure at a bound of its search range."""
        if name not in self.bounds:
            return "at the search bound"
        lo, hi, wl, wh = self.bounds[name]
        low = abs(math.log(self.estimate[name] / lo)) <= abs(math.log(self.estimate[name] / hi))
        return f"at its {'lower' if low else 'upper'} bound ({wl if low else wh}, {lo if low else hi:.3g})"

    def unidentified(self) -> str:
        """'R not identified: at its lower bound (...)', one clause per figure at a bound; '' if none."""
        return "; ".join(f"{f} not identified: {self.bound_said(f)}" for f in self.figures if f in self.at_bound)

    @property
    def chosen(self) -> dict[str, float]:
        return dict(self.estimate) if self.adopted else dict(self.start)


def all_figures(model: Model) -> dict[str, float]:
    """Every figure tune can set, with the model's values: the noise figures and c2 of each axis."""
    out = {f: float(getattr(model.noise, f)) for f in FIGURES}
    out.update({f"c2.{a.name}": float(a.c2) for a in model.axes})
    return out


def with_figures(model: Model, values: dict[str, float], *, check: bool = True) -> Model:
    """``model`` with the noise figures and c2.<axis> values in ``values`` replaced."""
    noise = {k: v for k, v in values.items() if not _is_c2(k)}
    c2 = {k[3:]: v for k, v in values.items() if _is_c2(k)}
    m = with_noise(model, **noise)
    if c2:
        m = dataclasses.replace(
            m, axes=tuple(dataclasses.replace(a, c2=float(c2[a.name])) if a.name in c2 else a for a in m.axes)
        )
    return revalidate(m) if check else m


def tune(
    model: Model,
    accel: np.ndarray,
    valid: np.ndarray,
    extras: Sequence[Sequence[Measurement]],
    **kw,
) -> TuneResult:
    """Maximum-likelihood figures (of sigma_n, sigma_eps, R, and "c2" for every axis's c2) from ``accel`` (N,
    axes) held in memory, one chunk; the keywords are :func:`search`'s."""
    return search(model, RunData.of(np.asarray(accel, dtype=np.float64), valid, extras), **kw)


def search(
    model: Model,
    data: RunData,
    *,
    figures: Sequence[str] = FIGURES,
    progress=None,
    max_evaluations: int = MAX_EVALUATIONS,
    max_seconds: float | None = None,
    intervals: bool = True,
) -> TuneResult:
    """Maximum-likelihood figures (of sigma_n, sigma_eps, R, and "c2" for every axis's c2) from ``data``, its
    likelihood computed chunk by chunk (every evaluation reads the run again).

    ``max_seconds`` bounds the search's wall time (the best point found by then is the estimate; the
    intervals are then skipped), checked after every chunk, so that an evaluation of a long run stops within a
    chunk of it; the first evaluation (the starting model) is timed, and when the bound will cut the search
    short that is said before it starts. ``intervals=False`` skips the Hessian and the profile intervals (se and
    intervals are NaN), for a caller that only wants the estimate.
    """
    figures = _figure_names(model, figures)
    start = all_figures(model)
    first = dict(start)
    if first["sigma_eps"] <= 0 and "sigma_eps" in figures:
        first["sigma_eps"] = 1e-6  # ln 0 is not a starting point
    span = model.max_accel_m_s2 / C2_SCALE
    bounds = figure_bounds(model)
    lo = np.array([-span if _is_c2(f) else math.log(bounds[f][0]) for f in figures])
    hi = np.array([span if _is_c2(f) else math.log(bounds[f][1]) for f in figures])
    count = [0]
    deadline = None  # set once the start is evaluated, so that there is always a best point
    best = [math.inf, None]

    def values(theta) -> dict[str, float]:
        th = np.clip(theta, lo, hi)
        return {f: float(t * C2_SCALE if _is_c2(f) else math.exp(t)) for f, t in zip(figures, th, strict=True)}

    def in_time(_done: int) -> None:
        if deadline is not None and time.monotonic() > deadline:
            raise _OutOfTime

    def nll(theta) -> float:
        in_time(0)
        count[0] += 1
        if progress is not None:
            progress.update(min(count[0], progress.total))
        try:
            m = with_figures(model, values(theta), check=False)
            v = -data_loglik(m, data, in_time)
        except ValueError:  # a covariance that is not positive definite at an extreme theta
            return 1e300
        # outside the bounds: the clipped value plus a penalty, so the search turns back
        v += 1e3 * float(np.sum(np.maximum(lo - theta, 0) ** 2 + np.maximum(theta - hi, 0) ** 2))
        if v < best[0]:
            best[0], best[1] = v, np.array(theta, dtype=np.float64)
        return v

    theta0 = np.array([first[f] / C2_SCALE if _is_c2(f) else math.log(first[f]) for f in figures])
    t0 = time.monotonic()
    ll0 = -nll(theta0)
    share = max(10, max_evaluations // (3 if intervals else 1))
    _say_pace(data, time.monotonic() - t0, share, max_seconds)
    deadline = None if max_seconds is None else time.monotonic() + max_seconds
    try:
        res = optimize.minimize(
            nll,
            theta0,
            method="Nelder-Mead",
            options={
                "xatol": 1e-3,
                "fatol": 1e-3,
                "maxfev": share,
                "initial_simplex": np.vstack([theta0] + [theta0 + 0.5 * e for e in np.eye(len(figures))]),
            },
        )
        converged = bool(res.success)
        theta = np.clip(res.x, lo, hi)
        deadline = None  # what follows is bounded by evaluations
        ll1 = -nll(theta)
    except _OutOfTime:  # the best point so far (its ln L is known: no further evaluation)
        converged, intervals = False, False
        theta, ll1 = np.clip(best[1], lo, hi), -best[0]
    deadline = None
    if ll1 < ll0:
        theta, ll1 = theta0, ll0
    est = dict(start)
    est.update(values(theta))
    k = len(figures)
    nan = float("nan")
    se = {f: nan for f in figures}
    ci = {f: (nan, nan) for f in figures}
    ends: dict[str, tuple[str, str]] = {}
    if intervals:
        se, ci, ends = _intervals(nll, theta, -ll1, figures, est, lo, hi, count, max_evaluations)
    lr = max(0.0, 2.0 * (ll1 - ll0))
    p = float(stats.chi2.sf(lr, k))
    return TuneResult(
        figures=figures,
        start=start,
        estimate=est,
        se_ln=se,
        ci95=ci,
        ll_start=ll0,
        ll_estimate=ll1,
        lr=lr,
        p_value=p,
        adopted=p < 0.05,
        evaluations=count[0],
        converged=converged,
        at_bound=_at_bound(figures, theta, lo, hi),
        ends=ends,
        bounds={f: bounds[f] for f in figures if not _is_c2(f)},
    )


def _say_pace(data: RunData, seconds: float, share: int, max_seconds: float | None) -> None:
    """Say, before the search, when its time bound will stop it short of its evaluations (a long run's)."""
    if max_seconds is None or seconds <= 0 or seconds * share <= max_seconds:
        return
    fit = int(max_seconds // seconds)
    note(
        f"tune: one likelihood evaluation of {data.n} samples x {data.n_axes} axes takes {seconds:.3g} s: about {fit} "
        f"of the search's {share} evaluations fit in {max_seconds:g} s; the best figures found by then are used"
    )


def _figure_names(model: Model, figures: Sequence[str]) -> tuple[str, ...]:
    """The figures asked for, "c2" expanded to one per axis; an unknown one refused."""
    names = []
    for f in figures:
        if f == "c2":
            names += [f"c2.{a.name}" for a in model.axes]
        elif f in FIGURES:
            names.append(f)
        else:
            raise ValueError(f"figure {f!r}; accepted: {', '.join(FIGURES)}, c2")
    return tuple(names)


def _hessian(nll, theta, f0, h: float = 0.02) -> np.ndarray:
    """The observed information: central differences of -ln L (``nll``, ``f0`` at ``theta``) in theta."""
    k = len(theta)
    H = np.empty((k, k))
    for i in range(k):
        for j in range(i, k):
            ei, ej = np.eye(k)[i] * h, np.eye(k)[j] * h
            if i == j:
                H[i, i] = (nll(theta + ei) - 2 * f0 + nll(theta - ei)) / h**2
            else:
                H[i, j] = H[j, i] = (
                    nll(theta + ei + ej) - nll(theta + ei - ej) - nll(theta - ei + ej) + nll(theta - ei - ej)
                ) / (4 * h**2)
    return H


def _intervals(nll, theta, f0, figures, est, lo, hi, count, max_evaluations):
    """(se, 95 % intervals, how each profile ended) at the estimate ``theta`` (-ln L there: ``f0``): the
    Wald se from the observed information, profile intervals for the noise figures, Wald ones for c2."""
    k = len(figures)
    H = _hessian(nll, theta, f0)
    # covariance on the well-determined directions; a figure that leans on a flat or curved-the-wrong-way
    # direction of -ln L (eigenvalue <= 0) gets no Wald se
    try:
        w, V = np.linalg.eigh(H)
    except np.linalg.LinAlgError:
        w, V = np.full(k, np.nan), np.eye(k)
    good = np.isfinite(w) & (w > 0)
    cov = (V[:, good] / w[good]) @ V[:, good].T
    weak = np.sum(V[:, ~good] ** 2, axis=1) > 0.1
    se = {}
    for i, f in enumerate(figures):
        se[f] = math.sqrt(cov[i, i]) if cov[i, i] > 0 and not weak[i] else float("nan")
    ci: dict[str, tuple[float, float]] = {}
    ends: dict[str, tuple[str, str]] = {}
    noise_figs = [f for f in figures if not _is_c2(f)]
    # profiles, best-determined figure first (cheap: its ends are near), so that what they leave goes to the
    # weakest (an undefined se counts as the weakest), whose profile may have to walk to a search bound
    noise_figs.sort(key=lambda f: se[f] if math.isfinite(se[f]) else math.inf)
    total = max_evaluations + 20  # the Hessian may take the search's evaluations past its share
    for n_fig, f in enumerate(noise_figs):
        i = figures.index(f)
        sides = []
        for side, direction in enumerate((-1.0, 1.0)):
            # a fair share of what is left, so that a figure whose profile wanders far cannot starve the others
            left = (len(noise_figs) - n_fig) * 2 - side
            limit = count[0] + max(0, total - count[0]) // left
            bound = lo[i] if direction < 0 else hi[i]
            psi, how = _profile_end(nll, theta, f0, i, direction, se[f], bound, lo, hi, H, count, limit)
            sides.append((psi, how))
        ends[f] = (sides[0][1], sides[1][1])
        ci[f] = tuple(math.exp(psi) if how != "budget" else float("nan") for psi, how in sides)
    for f in figures:
        if not _is_c2(f):
            continue
        if not math.isfinite(se[f]):
            ci[f] = (float("nan"), float("nan"))
        else:
            se[f] *= C2_SCALE
            ci[f] = (est[f] - 1.96 * se[f], est[f] + 1.96 * se[f])
    return se, ci, ends


def tune_run(
    model: Model,
    run,
    *,
    fixes=None,
    rest: np.ndarray | None = None,
    rest_sigma: np.ndarray | None = None,
    params=None,
    figures: Sequence[str] = FIGURES,
    max_evaluations: int = MAX_EVALUATIONS,
    max_seconds: float | None = None,
    intervals: bool = False,
    announce=None,
) -> tuple[Model, TuneResult]:
    """The model with this run's maximum-likelihood noise figures, found with the run's aids (fixes, rests)
    in a stated budget; and the result. ``accelnav.tune`` asks for the intervals too, ``accelnav smooth
    --tune`` only for the estimate. The run is held in memory (one chunk); :func:`tune_data` reads one a chunk
    at a time.

    The figures are rounded to 6 digits, as a model file holds them. ``announce(samples, axes, aids)`` is
    called once before the search, which may take the whole budget."""
    _check_budget(max_evaluations, max_seconds)
    accel = np.asarray(run["accel"], dtype=np.float64)
    n, m = accel.shape
    extras, _ = aid_measurements(n, m, model, fixes=fixes, rest=rest, rest_sigma=rest_sigma, params=params)
    data = RunData.of(accel, ~np.asarray(run["clipped"], dtype=bool), extras)
    return tune_data(model, data, figures=figures, max_evaluations=max_evaluations, max_seconds=max_seconds,
                     intervals=intervals, announce=announce)  # fmt: skip


def tune_data(model: Model, data: RunData, *, announce=None, **bounds) -> tuple[Model, TuneResult]:
    """:func:`tune_run` of a run read chunk by chunk (``data``: its aids made already), in the memory of a chunk
    whatever the run's length; ``bounds``: :func:`search`'s keywords (``intervals`` False unless given)."""
    bounds = {"intervals": False, **bounds}
    _check_budget(bounds.get("max_evaluations", MAX_EVALUATIONS), bounds.get("max_seconds"))
    if announce is not None:
        announce(data.n, data.n_axes, data.count)
    if "figures" in bounds:
        bounds["figures"] = tuple(bounds["figures"])
    r = search(model, data, **bounds)
    return with_figures(model, {f: float(f"{v:.6g}") for f, v in r.chosen.items()}), r


def _check_budget(max_evaluations: int, max_seconds: float | None) -> None:
    if max_evaluations < 10:
        raise ValueError(f"max_evaluations: got {max_evaluations}; accepted: 10 or more")
    if max_seconds is not None and not max_seconds > 0:
        raise ValueError(f"max_seconds: got {max_seconds:g}; accepted: a time > 0 s")


class _OutOfTime(Exception):
    """The search's wall-time budget ran out (caught in tune)."""


def _at_bound(figures, theta, lo, hi) -> tuple[str, ...]:
    return tuple(f for f, t, a, b in zip(figures, theta, lo, hi, strict=True) if t <= a + 0.05 or t >= b - 0.05)


def _profile_end(nll, theta, f0, i, direction, se, bound, lo, hi, H, count, limit) -> tuple[float, str]:
    """ln(figure) where the profile of -ln L in theta[i] rises PROFILE_DROP above f0, going ``direction``.

    Returns (value, "closed"), (bound, "open") when the profile stays below the drop up to the search bound,
    or (nan, "budget") when ``count`` reaches ``limit`` first. The other coordinates are re-optimised at
    every step (Nelder-Mead from the linear prediction of the Hessian ``H`` where it is positive definite,
    else from the previous step's optimum).
    """
    k = len(theta)
    others = [j for j in range(k) if j != i]
    psi_hat = float(theta[i])
    predict = None
    if others:
        Hoo = H[np.ix_(others, others)]
        try:
            np.linalg.cholesky(Hoo)
            predict = -np.linalg.solve(Hoo, H[others, i])  # d theta_others / d psi
        except np.linalg.LinAlgError:
            predict = None
    last = theta[others].copy() if others else None

    def profile(psi: float) -> float:
        nonlocal last
        if not others:
            return nll(np.array([psi])) if count[0] < limit else float("nan")

        def inner(x):
            full = np.array(theta, dtype=np.float64)
            full[i] = psi
            full[others] = x
            return nll(full)

        room = limit - count[0]
        if room < 2 * len(others) + 4:
            return float("nan")
        # start from the Hessian's linear prediction or from the previous step's optimum, whichever fits better
        start = np.clip(last, lo[others], hi[others])
        if predict is not None:
            guess = np.clip(theta[others] + predict * (psi - psi_hat), lo[others], hi[others])
            if inner(guess) < inner(start):
                start = guess
        r = optimize.minimize(
            inner,
            start,
            method="Nelder-Mead",
            options={
                "xatol": 2e-3,
                "fatol": 2e-3,
                "maxfev": min(room, 60 * len(others)),
                "initial_simplex": np.vstack([start] + [start + 0.05 * e for e in np.eye(len(others))]),
            },
        )
        last = r.x
        return float(r.fun)

    def root(psi: float) -> float:
        v = profile(psi)
        return math.sqrt(2.0 * max(v - f0, 0.0)) if math.isfinite(v) else float("nan")

    step = 1.96 * se if math.isfinite(se) and se > 0 else 0.5
    step = min(max(step, 0.02), 3.0)
    below = (psi_hat, 0.0)  # (psi, r) with r < R95, nearest the end found so far
    above = None  # (psi, r) with r > R95
    psi = psi_hat + direction * step
    for _ in range(16):
        at_bound = (psi - bound) * direction >= 0
        if at_bound:
            psi = bound
        r = root(psi)
        if not math.isfinite(r):
            return float("nan"), "budget"
        if abs(r - R95) < 0.02:
            return psi, "closed"
        if r < R95:
            if at_bound:
                return bound, "open"
            below = (psi, r)
        else:
            above = (psi, r)
        if above is not None:
            (p0, r0), (p1, r1) = below, above
            if abs(p1 - p0) < 5e-3:
                return p0 + (p1 - p0) * (R95 - r0) / (r1 - r0), "closed"
            # the signed root is nearly linear in psi: interpolate, kept inside the bracket
            x = (R95 - r0) / (r1 - r0)
            psi = p0 + (p1 - p0) * min(max(x, 0.1), 0.9)
        else:
            (p0, r0) = below
            slope = (r0 - 0.0) / (p0 - psi_hat) if p0 != psi_hat else 0.0
            dist = abs(p0 - psi_hat)
            if slope * direction > 0:
                want = abs((R95 - r0) / slope)
                dist_next = min(max(want * 1.05, 0.2 * dist), 3.0 * dist + 0.5)
            else:
                dist_next = 2.0 * dist + 0.5
            psi = p0 + direction * dist_next
    (p0, r0) = below
    if above is not None:
        (p1, r1) = above
        return p0 + (p1 - p0) * (R95 - r0) / (r1 - r0), "closed"
    return float("nan"), "budget"


def aid_measurements(
    n: int,
    n_axes: int,
    model: Model,
    *,
    fixes: Sequence[Sequence[Measurement]] | None = None,
    rest: np.ndarray | None = None,
    rest_sigma: np.ndarray | None = None,
    params=None,
) -> tuple[list[list[Measurement]], list[int]]:
    """Per axis: the position fixes, then the zero-velocity updates of ``rest`` ((N,) or (N, n_axes)), as the
    extra measurements tune and the smoother take; and the number of zero-velocity updates per axis."""
    from accelnav.estimate import zupt

    params = zupt.ZuptParams() if params is None else params
    extras = [list(fixes[j]) if fixes is not None else [] for j in range(n_axes)]
    n_zupt = [0] * n_axes
    if rest is not None:
        r2 = np.broadcast_to(rest[:, None] if rest.ndim == 1 else rest, (n, n_axes))
        for j in range(n_axes):
            sigma = None if rest_sigma is None else np.asarray(rest_sigma)[:, j]
            zs = zupt.axis_updates(r2[:, j], sigma, model, params)[1]
            extras[j] += zs
            n_zupt[j] = len(zs)
    return extras, n_zupt
