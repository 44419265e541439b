"""Does the model fit the data? Innovation checks and the fix-only baselines a smoother must beat.

NIS
---
In a Kalman filter whose model is right, each scalar innovation y of an aid (position fix, zero-velocity
update) has variance S as the filter predicts, and the innovations are white, so the sum of y^2 / S over N
updates is chi^2 with N degrees of freedom. A mean NIS above the chi^2_N 99.9 % point / N says the aids
disagree with the model by more than its noise figures allow (the figures are too stiff); one below the
0.1 % point / N says the figures are too loose. The innovations are replayed from the forward filter's
priors at the aided samples only (acceleration update first, then the sample's aids in order), so the
plain path, which has no aids, pays nothing.

Baselines with fixes
--------------------
Two things a user can do with fixes alone, which a smoother given the same fixes must not lose to:

* :func:`interpolate_fixes`: straight lines between the fixes;
* :func:`fix_to_fix_integration`: the classic post-processing, double integration of the acceleration
  (less the model's mean bias) from each fix, with the start speed chosen so that the track lands
  on the next fix. That is the double integral plus the straight line through its misses at the fixes.

Without truth, :func:`holdout` compares them on fixes left out: every other fix is hidden, each method
predicts it from the rest. Fewer than ``HOLDOUT_MIN`` held-out fixes cannot tell the methods apart (below).

Rests re-examined
-----------------
A rest that disagrees with the model is first suspected of not being a rest:
:func:`accelnav.estimate.pipeline.disagreeing_rests` tests each rest's zero velocity against a smoothing that
did not use it, and names the ones that fail, before any line blames the noise figures.
Two kinds of evidence, in this order:

* **the fixes**: one smoothing with the fixes alone; a rest whose mean smoothed velocity is off zero by more
  than that smoothing's velocity sd allows (chi-square, one dof per axis; the sd scaled up by the fixes' own
  mean NIS where that is above 1, so a model too stiff for the fixes does not condemn true rests) is dropped,
  all such rests at once: no rest vouches for another here;
* **the other rests**: leave-one-out. The rests whose first update's NIS (the velocity gathered since the
  previous aid, forward) stands out are smoothed without each in turn, the worst dropped if its velocity there
  is off zero, and the rest re-smoothed, one at a time (a false rest makes its true neighbour look wrong too:
  dropping the worst first clears it). Each statistic is taken relative to the median rest's (a model too stiff
  for all rests inflates them all alike, and is the noise lines' business, not a reason to drop rests); so
  rests that are mostly false, with no fixes, cannot be told from true ones, and none is dropped for it.

Each rest is held to the chi-square point that a true rest passes with probability 1 - ``REST_ALPHA`` / (the
number of rests): over the whole run, one true rest dropped in a thousand runs.

Advice
------
"try --tune" is printed only where tuning can help: when the fixes' NIS is off and the model was not just
tuned. Rests cannot ask for it: a rest that is not one (a cruise called still) disagrees with any noise
figures, and tuning to it inflates them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from accelnav.estimate.kf import Aids, Measurement, batch_update, double_integrate
from accelnav.lazy import lazy_module
from accelnav.model.design import AxisDesign

# chi2.ppf(q, n) is 2 gammaincinv(n / 2, q): scipy.special imports in a tenth of scipy.stats' 1-2 s, which
# every `smooth` with aids paid
special = lazy_module("scipy.special")

NIS_QUANTILE = 0.999  # two-sided: above the 99.9 % point, too stiff; below the 0.1 % point, too loose


def aid_innovations(
    d: AxisDesign,
    z: np.ndarray,
    valid: np.ndarray,
    x_prior: np.ndarray,
    P_prior: np.ndarray,
    extras: Sequence[Measurement],
) -> tuple[np.ndarray, np.ndarray]:
    """(y, S) of each aid in ``extras`` (its given order), replayed from the priors of the forward pass.

    ``P_prior`` is (N, 4, 4). Every aid must have been applied by the filter (a gated-out one changed
    nothing: leave it out). See :func:`aid_innovations_arrays`.
    """
    a = Aids.of(extras)
    return aid_innovations_arrays(d, z, valid, x_prior, P_prior, a.k, a.h, a.z, a.R)


# packed index (accelnav.estimate.fastsmooth.PACKED) of each entry of a 4x4, row-major
_FULL = np.array([0, 1, 2, 3, 1, 4, 5, 6, 2, 5, 7, 8, 3, 6, 8, 9])


def aid_innovations_arrays(d: AxisDesign, z, valid, x_prior, P_prior, ks, hs, zs, rs) -> tuple[np.ndarray, np.ndarray]:
    """:func:`aid_innovations` of aids given as arrays (samples ``ks``, rows ``hs``, values ``zs``, variances
    ``rs``). ``P_prior`` is (N, 4, 4) or packed (N, 10) as the compiled smoother returns it: only the rows
    of the aids' samples are unpacked. Samples are independent of each other given their priors, so all
    are replayed at once, one rank of same-sample aids after the other.
    """
    ks = np.asarray(ks, dtype=np.int64)
    ne = len(ks)
    if ne == 0:
        return np.zeros(0), np.zeros(0)
    hs, zs, rs = (np.asarray(v, dtype=np.float64) for v in (hs, zs, rs))
    order = np.argsort(ks, kind="stable")
    uk, first, group = np.unique(ks[order], return_index=True, return_inverse=True)
    rank = np.arange(ne) - first[group]
    X = np.array(x_prior[uk], dtype=np.float64)
    P = np.asarray(P_prior)[uk]
    P = np.array(P.take(_FULL, axis=1).reshape(-1, 4, 4) if P.ndim == 2 else P, dtype=np.float64)
    ok = np.asarray(valid, dtype=bool)[uk] & np.isfinite(z[uk])
    # the sample's acceleration update comes first: z = a + eps + v
    h_acc = np.broadcast_to(np.array([0.0, 0.0, 1.0, 1.0]), (int(ok.sum()), 4))
    X[ok], P[ok], _, _ = batch_update(X[ok], P[ok], h_acc, z[uk][ok], np.full(int(ok.sum()), d.R))
    y_out, S_out = np.empty(ne), np.empty(ne)
    for r in range(int(rank.max()) + 1):
        sel = np.flatnonzero(rank == r)
        g = group[sel]
        idx = order[sel]
        X[g], P[g], y, S = batch_update(X[g], P[g], hs[idx], zs[idx], rs[idx])
        y_out[idx], S_out[idx] = y, S
    return y_out, S_out


@dataclass(frozen=True)
class NisCheck:
    """Mean normalised innovation squared of one kind of aid against its chi^2 bounds."""

    kind: str  # "fixes" or "rests" (zero-velocity updates)
    n: int
    mean: float
    low: float  # chi^2_n 0.1 % point / n
    high: float  # chi^2_n 99.9 % point / n

    @property
    def verdict(self) -> str:
        """'stiff', 'loose' or '' (consistent)."""
        if self.n == 0 or not math.isfinite(self.mean):
            return ""
        return "stiff" if self.mean > self.high else "loose" if self.mean < self.low else ""

    def line(self, tuned: bool = False) -> str:
        """One line: the figure, and what it says about the model; ``tuned``: the model was just fitted to this
        run (accelnav smooth --tune), so tuning is not advised again."""
        what = "position fixes" if self.kind == "fixes" else "rests (first zero-velocity update of each)"
        fig = f"mean NIS {self.mean:.3g} over {self.n} {self.kind}"
        if self.verdict == "stiff":
            head = f"{self.kind} disagree with the {'tuned ' if tuned else ''}model: {fig}, bound {self.high:.3g}"
            if self.kind != "fixes":
                return (
                    f"{head}: the noise figures may be too stiff or the rests not quite still; only fixes can tell "
                    "(tuning on rests takes them as truth)"
                )
            if tuned:
                return f"{head}: tuning does not fit them: check the fixes' sigma_m and any fix far off the track"
            return f"{head}; the model's noise figures are too stiff: try --tune"
        if self.verdict == "loose":
            head = (
                f"{self.kind} agree with the {'tuned ' if tuned else ''}model better than it expects: {fig}, "
                f"bound {self.low:.3g}"
            )
            if self.kind != "fixes":
                return (
                    f"{head}: the noise figures may be too loose, or rests follow each other with no motion "
                    "between (one stop in pieces, or a steady cruise called still); only fixes can tell"
                )
            if tuned:
                return f"{head}: the fixes' sigma_m may be larger than their real error"
            return f"{head}; the model's noise figures are too loose: try --tune"
        return f"{what}: {fig}, within [{self.low:.3g}, {self.high:.3g}]: consistent with the model"


def nis_check(kind: str, nis: np.ndarray) -> NisCheck:
    """The check of ``nis`` (y^2 / S of every update of one kind, all axes together)."""
    nis = np.asarray(nis, dtype=np.float64)
    n = len(nis)
    if n == 0:
        return NisCheck(kind, 0, math.nan, math.nan, math.nan)
    lo = 2.0 * float(special.gammaincinv(n / 2, 1 - NIS_QUANTILE)) / n
    hi = 2.0 * float(special.gammaincinv(n / 2, NIS_QUANTILE)) / n
    return NisCheck(kind, n, float(np.mean(nis)), lo, hi)


def first_rest_nis(rows: np.ndarray, t0: float) -> np.ndarray:
    """The NIS of each rest's first update from zupt_nis ``rows`` [t, axis, NIS, first], but of a rest at the run's
    first sample ``t0``: there the filter's prior already holds u = 0 exactly, the same statement, so its NIS is 0
    by construction and tests nothing."""
    first = (rows[:, 3] > 0) & (rows[:, 0] > t0)
    return rows[first, 2]


HOLDOUT_MIN = 5  # held-out fixes to judge on: the smoother losing at all of 4 has chance 1/16 > 5 % (sign test)
ANCHOR_SD = 1.0  # m: a final position sd above this with nothing anchoring the run is said


def sign_test(wins: int, n: int) -> float:
    """One-sided p of ``wins`` or more out of ``n`` fair coin flips."""
    return sum(math.comb(n, k) for k in range(wins, n + 1)) / 2.0**n


@dataclass(frozen=True)
class NoAnchor:
    """Rests were asked for, there are no fixes, and the position's sd at the end is above ANCHOR_SD: nothing
    anchors the run, or nothing since its last rest."""

    sd: float  # m, the largest final position sd over the axes
    axis: str
    still_s: float  # s, the still start that would anchor the run (ZuptParams.start_s)
    last_rest_s: float | None = None  # s, where the last rest applied ends; None: no rest applied

    def line(self) -> str:
        since = "no rest applied" if self.last_rest_s is None else f"no rest applied after {self.last_rest_s:.3g} s"
        gives = (
            f"a still start of {self.still_s:g} s, position fixes (--fixes) or a rest file (--zupt FILE)"
            if self.last_rest_s is None
            else "position fixes (--fixes) or a rest file (--zupt FILE)"
        )
        return (
            f"{since} and no fixes: nothing anchors the position, whose sd reaches {self.sd:.3g} m at the end "
            f"(axis {self.axis}); {gives} would give one"
        )


@dataclass(frozen=True)
class SmoothChecks:
    """What a smoothed run says about its model: the NIS of each kind of aid, with fixes the held-out
    comparison (:func:`accelnav.estimate.pipeline.holdout`, or None), the re-examination of the rests
    (:func:`accelnav.estimate.pipeline.disagreeing_rests`, or None), and whether anything anchors the run;
    :func:`accelnav.estimate.pipeline.smooth_checks` makes one. ``tuned``: the model was fitted to this run."""

    nis: tuple[NisCheck, ...]
    holdout: object | None
    review: RestReview | None = None
    tuned: bool = False
    no_anchor: NoAnchor | None = None

    @property
    def tune_helps(self) -> bool:
        """Whether to advise --tune: the fixes' NIS is off and the model was not just tuned (see the module)."""
        return not self.tuned and any(c.kind == "fixes" and c.verdict for c in self.nis)

    def lines(self) -> list[str]:
        """A line per check, as ``accelnav smooth`` prints them: the rests' re-examination first."""
        out = [] if self.review is None or not self.review.said else [self.review.line()]
        out += [c.line(self.tuned) for c in self.nis]
        h = self.holdout
        if h is not None:
            out += holdout_lines(h, self.tune_helps)
        if self.no_anchor is not None:
            out.append(self.no_anchor.line())
        return out


def holdout_lines(h, tune_helps: bool) -> list[str]:
    """The held-out comparison (:class:`accelnav.estimate.pipeline.Holdout`) in a line or two."""
    if h.n < HOLDOUT_MIN:
        return [
            f"held-out fixes (every other one left out): {h.n} predicted, too few to judge the smoother against "
            f"fixes alone: {HOLDOUT_MIN} at least (losing at all of fewer has a chance above 5 %)"
        ]
    out = [
        f"held-out fixes (every other one left out, {h.n} predicted): rms miss "
        + ", ".join(f"{k} {v:.3g} m" for k, v in h.rms.items())
    ]
    worse = h.worse_than()
    if worse:
        lost = min(h.losses(b) for b in worse)
        out.append(
            f"the smoother misses the held-out fixes more than {' and '.join(worse)} ({h.rms['smoother']:.3g} m "
            f"against {min(h.rms[b] for b in worse):.3g} m, further at {lost} of {h.n}): its model does not fit "
            "this recording" + (": try --tune" if tune_helps else "")
        )
    return out


REST_ALPHA = 1e-3  # a true rest dropped in one run of a thousand (see the module)
REVIEW_SMOOTHINGS = 60  # leave-one-out smoothings of the rests at most
REVIEW_SUSPECTS = 4  # rests smoothed without themselves per round: the ones whose first update stands out most
REVIEW_MEDIAN_MIN = 5  # rests at least for their median to set what is usual; fewer: the model's own chi-square
_LISTED = 4  # rests named in the line


@dataclass(frozen=True)
class RestTest:
    """One rest [start, stop) tested against a smoothing that did not use it."""

    start: int
    stop: int
    chi2: float  # sum over axes of (mean smoothed velocity)^2 / (its variance + the rest's own), scaled
    dof: int  # axes
    bound: float  # the chi-square point it is held to
    speed: float  # m/s, |mean smoothed velocity| over the axes
    against: str  # "the fixes" or "the other rests"

    @property
    def fails(self) -> bool:
        return self.chi2 > self.bound


@dataclass(frozen=True)
class RestReview:
    """The rests re-examined (:func:`accelnav.estimate.pipeline.disagreeing_rests`): the ones dropped, and how far
    the test got."""

    tested: int  # rests
    dropped: tuple[RestTest, ...]
    smoothings: int
    complete: bool  # False: REVIEW_SMOOTHINGS ran out with suspects left
    kept: np.ndarray  # (N, n_axes) the rest mask less the dropped rests
    t: np.ndarray  # the run's times, for the line
    undecided: bool = False  # a rest stands out, but too few rests are left to say which is wrong
    # the review's last smoothing, made with exactly ``kept``'s rests (covariances off), or None: the one-chunk
    # path's output when nothing after the review changes the aids (accelnav.estimate.engine.run), not made twice
    smoothed: dict | None = field(default=None, repr=False, compare=False)

    @property
    def said(self) -> bool:
        return bool(self.dropped) or not self.complete or self.undecided

    def line(self) -> str:
        n = len(self.dropped)
        worst = sorted(self.dropped, key=lambda r: -r.chi2)[:_LISTED]
        named = "; ".join(
            f"{self.t[r.start]:.3g}-{self.t[r.stop - 1]:.3g} s (against {r.against}: {r.speed:.2g} m/s, chi2 "
            f"{r.chi2:.3g} > {r.bound:.3g})"
            for r in worst
        )
        more = f"; {n - len(worst)} more" if n > len(worst) else ""
        head = f"rests re-examined: {n} of {self.tested} disagree with the rest of the evidence, dropped"
        tail = "" if self.complete else f"; stopped at its budget ({self.smoothings} smoothings) with suspects left"
        if self.undecided:
            tail += "; the rests left disagree, but two cannot say which of them is wrong (fixes could)"
        return head + (f": {named}{more}" if n else "") + tail


def rest_bound(dof: int, n_tests: int) -> float:
    """The chi-square (``dof``) point a true rest exceeds with probability REST_ALPHA / n_tests."""
    return 2.0 * float(special.gammainccinv(dof / 2.0, REST_ALPHA / max(n_tests, 1)))


def rest_tests(
    smoothed: dict,
    rests: Sequence[tuple[int, int]],
    updates: np.ndarray,
    sigma: np.ndarray,
    against: str,
    n_tests: int,
    scale: float = 1.0,
    var_scale: float = 1.0,
) -> list[RestTest]:
    """Each rest [a, b) of ``rests`` against ``smoothed`` (a smoothing that did not use it): on each axis with
    zero-velocity updates there (``updates`` (N, n_axes) bool, their sds ``sigma`` (N, n_axes)), the mean
    smoothed velocity against its variance (``var_scale`` times the mean smoothed one: the samples of a rest
    are nearly one velocity, so the mean's variance is about theirs) plus the updates' own (1 / sum 1/sigma^2);
    the sum over axes divided by ``scale``."""
    u = smoothed["smooth_x"][:, :, 1]
    vu = smoothed["smooth_sd"][:, :, 1] ** 2
    out = []
    for a, b in rests:
        chi2, speed2, dof = 0.0, 0.0, 0
        for j in range(u.shape[0]):
            ks = a + np.flatnonzero(updates[a:b, j])
            if not len(ks):
                continue
            ub = float(u[j, ks].mean())
            own = 1.0 / float(np.sum(1.0 / sigma[ks, j] ** 2))
            chi2 += ub * ub / (var_scale * float(vu[j, ks].mean()) + own)
            speed2 += ub * ub
            dof += 1
        if dof:
            out.append(RestTest(a, b, chi2 / scale, dof, rest_bound(dof, n_tests), math.sqrt(speed2), against))
    return out


def chi2_median(dof: int) -> float:
    return 2.0 * float(special.gammaincinv(dof / 2.0, 0.5))


def first_update_nis(smoothed: dict, rests: list[tuple[int, int]]) -> np.ndarray:
    """Per rest, the sum over axes of the NIS of its first zero-velocity update (smooth_run's zupt_nis)."""
    rows = smoothed["zupt_nis"]
    first = rows[rows[:, 3] > 0]
    t = np.asarray(smoothed["t"])
    starts = np.array([t[a] for a, _ in rests])
    stops = np.array([t[b - 1] for _, b in rests])
    which = np.searchsorted(starts, first[:, 0], side="right") - 1
    ok = (which >= 0) & (first[:, 0] <= stops[np.clip(which, 0, None)])
    return np.bincount(which[ok], weights=first[ok, 2], minlength=len(rests))


def _fix_points(t: np.ndarray, fixes: Sequence[Measurement]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k, t, z) of the fixes by time; of several fixes on one sample, their mean."""
    ks = np.array([m.k for m in fixes], dtype=np.int64)
    zs = np.array([m.z for m in fixes], dtype=np.float64)
    uk, inv = np.unique(ks, return_inverse=True)
    zm = np.bincount(inv, weights=zs) / np.bincount(inv)
    return uk, np.asarray(t)[uk], zm


def interpolate_fixes(t: np.ndarray, fixes: Sequence[Measurement]) -> np.ndarray:
    """(N,) position from straight lines between the fixes (held before the first and after the last)."""
    if not fixes:
        return np.full(len(t), np.nan)
    _, tf, zf = _fix_points(t, fixes)
    return np.interp(t, tf, zf)


def fix_to_fix_integration(
    d: AxisDesign, t: np.ndarray, accel: np.ndarray, valid: np.ndarray, fixes: Sequence[Measurement]
) -> np.ndarray:
    """(N,) position from double integration between fixes, each leg landing on the next fix.

    The acceleration less the model's mean bias (the filter's prior eps, relaxing at phi per sample to
    c1 + c2) is integrated once over the run; on each leg the start speed that lands on the next fix adds
    a straight line, so the track is that integral plus the interpolated misses at the fixes. Before the
    first fix and after the last the leg next to it is extended.
    """
    if not fixes:
        return np.full(len(t), np.nan)
    m = d.eps_mean
    eps = m + (float(d.x0[3]) - m) * d.phi ** np.arange(len(t))
    r = double_integrate(d, np.asarray(accel) - eps, valid)[:, 0]
    kf, tf, zf = _fix_points(t, fixes)
    miss = zf - r[kf]
    if len(kf) == 1:
        return r + miss[0]
    line = np.interp(t, tf, miss)
    # extend the first and last legs' lines (np.interp would hold the miss, i.e. land with the wrong speed)
    for sel, (i0, i1) in ((t < tf[0], (0, 1)), (t > tf[-1], (-2, -1))):
        slope = (miss[i1] - miss[i0]) / (tf[i1] - tf[i0])
        line[sel] = miss[i0] + slope * (np.asarray(t)[sel] - tf[i0])
    return r + line
