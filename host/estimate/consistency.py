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
predicts it from the rest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

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

    def line(self) -> str:
        """One line: the figure, and what it says about the model."""
        what = "position fixes" if self.kind == "fixes" else "rests (first zero-velocity update of each)"
        head = f"{what}: mean NIS {self.mean:.3g} over {self.n}"
        if self.verdict == "stiff":
            return (
                f"{self.kind} disagree with the model: mean NIS {self.mean:.3g} over {self.n} {self.kind}, bound "
                f"{self.high:.3g}; the model's noise figures are too stiff: try --tune"
            )
        if self.verdict == "loose":
            return (
                f"{self.kind} agree with the model better than it expects: mean NIS {self.mean:.3g} over {self.n} "
                f"{self.kind}, bound {self.low:.3g}; the model's noise figures are too loose: try --tune"
            )
        return f"{head}, within [{self.low:.3g}, {self.high:.3g}]: consistent with the model"


def nis_check(kind: str, nis: np.ndarray) -> NisCheck:
    """The check of ``nis`` (y^2 / S of every update of one kind, all axes together)."""
    nis = np.asarray(nis, dtype=np.float64)
    n = len(nis)
    if n == 0:
        return NisCheck(kind, 0, math.nan, math.nan, math.nan)
    lo = 2.0 * float(special.gammaincinv(n / 2, 1 - NIS_QUANTILE)) / n
    hi = 2.0 * float(special.gammaincinv(n / 2, NIS_QUANTILE)) / n
    return NisCheck(kind, n, float(np.mean(nis)), lo, hi)


@dataclass(frozen=True)
class SmoothChecks:
    """What a smoothed run says about its model: the NIS of each kind of aid, and with fixes the held-out
    comparison (:func:`accelnav.estimate.pipeline.holdout`, or None); :func:`accelnav.estimate.pipeline.smooth_checks`
    makes one."""

    nis: tuple[NisCheck, ...]
    holdout: object | None

    def lines(self) -> list[str]:
        """A line per check, as ``accelnav smooth`` prints them."""
        out = [c.line() for c in self.nis]
        h = self.holdout
        if h is None:
            return out
        out.append(
            f"held-out fixes (every other one left out, {h.n} predicted): rms miss "
            + ", ".join(f"{k} {v:.3g} m" for k, v in h.rms.items())
        )
        worse = h.worse_than()
        if worse:
            out.append(
                f"the smoother misses the held-out fixes more than {' and '.join(worse)} "
                f"({h.rms['smoother']:.3g} m against {min(h.rms[b] for b in worse):.3g} m): its model does not "
                "fit this recording: try --tune"
            )
        return out


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
