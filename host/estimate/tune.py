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
reverts to), maximised by Nelder-Mead from the
starting model's values; 95 % intervals from the observed information (the central-difference Hessian of
-ln L in theta): exp(theta +- 1.96 se), a factor, so the interval of a positive figure stays positive. A
figure whose se(ln) exceeds ``NOT_IDENTIFIED_SE`` is reported as not identified by the data.

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
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from accelnav.codegen.design import axis_design
from accelnav.codegen.model import Model
from accelnav.codegen.modelfile import revalidate, with_noise
from accelnav.estimate import fastsmooth
from accelnav.estimate.kf import Measurement

FIGURES = ("sigma_n", "sigma_eps", "R")
NOT_IDENTIFIED_SE = 1.0  # se of ln(figure): a 95 % interval wider than a factor e^(2 x 1.96) ~ 50
MAX_EVALUATIONS = 400
LN_BOUNDS = {"sigma_n": (1e-4, 1e3), "sigma_eps": (1e-9, 10.0), "R": (1e-10, 1e4)}


def _axis_loglik(model: Model, j: int, z: np.ndarray, valid: np.ndarray, extras: Sequence[Measurement]) -> float:
    d = axis_design(model, j)
    # the general path: the plain one caches gains per design, and every theta is a new design
    res = fastsmooth.smooth_general(d, z, valid=valid, extras=list(extras))
    xp = res.x_prior
    Pp = fastsmooth.unpack(res.P_prior)
    S = Pp[:, 2, 2] + 2.0 * Pp[:, 2, 3] + Pp[:, 3, 3] + d.R
    y = z - (xp[:, 2] + xp[:, 3])
    ok = valid & np.isfinite(z)
    ll = -0.5 * float(np.sum(np.log(2.0 * math.pi * S[ok]) + y[ok] ** 2 / S[ok]))
    h_z = np.array([0.0, 0.0, 1.0, 1.0])
    by_k: dict[int, list[Measurement]] = {}
    for m in extras:
        by_k.setdefault(m.k, []).append(m)
    for k, ms in by_k.items():
        x = xp[k].copy()
        P = Pp[k].copy()
        if ok[k]:
            x, P = _update(x, P, h_z, z[k], d.R)
        for m in ms:
            h = np.asarray(m.h, dtype=np.float64)
            Se = float(h @ P @ h) + m.R
            ye = m.z - float(h @ x)
            ll -= 0.5 * (math.log(2.0 * math.pi * Se) + ye * ye / Se)
            x, P = _update(x, P, h, m.z, m.R)
    return ll


def _update(x, P, h, z, R):
    Ph = P @ h
    S = float(h @ Ph) + R
    K = Ph / S
    x = x + K * (z - float(h @ x))
    P = P - np.outer(K, Ph)
    return x, 0.5 * (P + P.T)


def loglik(model: Model, accel: np.ndarray, valid: np.ndarray, extras: Sequence[Sequence[Measurement]]) -> float:
    """ln L of the accelerations (N, axes) and each axis's extra measurements under ``model``."""
    return sum(_axis_loglik(model, j, accel[:, j], valid[:, j], extras[j]) for j in range(accel.shape[1]))


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

    def identified(self, name: str) -> bool:
        if name in self.at_bound:
            return False
        s = self.se_ln[name]
        if _is_c2(name):
            return math.isfinite(s) and s <= NOT_IDENTIFIED_SE * C2_SCALE * 10  # c2 known to 0.1 m/s^2 (10 mg)
        return math.isfinite(s) and s <= NOT_IDENTIFIED_SE

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
    *,
    figures: Sequence[str] = FIGURES,
    progress=None,
    max_evaluations: int = MAX_EVALUATIONS,
) -> TuneResult:
    """Maximum-likelihood figures (of sigma_n, sigma_eps, R, and "c2" for every axis's c2) from ``accel``."""
    names = []
    for f in figures:
        if f == "c2":
            names += [f"c2.{a.name}" for a in model.axes]
        elif f in FIGURES:
            names.append(f)
        else:
            raise ValueError(f"figure {f!r}; accepted: {', '.join(FIGURES)}, c2")
    figures = tuple(names)
    start = all_figures(model)
    first = dict(start)
    if first["sigma_eps"] <= 0 and "sigma_eps" in figures:
        first["sigma_eps"] = 1e-6  # ln 0 is not a starting point
    span = model.max_accel_m_s2 / C2_SCALE
    lo = np.array([-span if _is_c2(f) else math.log(LN_BOUNDS[f][0]) for f in figures])
    hi = np.array([span if _is_c2(f) else math.log(LN_BOUNDS[f][1]) for f in figures])
    count = [0]

    def values(theta) -> dict[str, float]:
        th = np.clip(theta, lo, hi)
        return {f: float(t * C2_SCALE if _is_c2(f) else math.exp(t)) for f, t in zip(figures, th, strict=True)}

    def nll(theta) -> float:
        count[0] += 1
        if progress is not None:
            progress.update(min(count[0], progress.total))
        try:
            m = with_figures(model, values(theta), check=False)
            v = -loglik(m, accel, valid, extras)
        except ValueError:  # a covariance that is not positive definite at an extreme theta
            return 1e300
        # outside the bounds: the clipped value plus a penalty, so the search turns back
        return v + 1e3 * float(np.sum(np.maximum(lo - theta, 0) ** 2 + np.maximum(theta - hi, 0) ** 2))

    theta0 = np.array([first[f] / C2_SCALE if _is_c2(f) else math.log(first[f]) for f in figures])
    ll0 = -nll(theta0)
    res = optimize.minimize(
        nll,
        theta0,
        method="Nelder-Mead",
        options={
            "xatol": 1e-3,
            "fatol": 1e-3,
            "maxfev": max_evaluations,
            "initial_simplex": np.vstack([theta0] + [theta0 + 0.5 * e for e in np.eye(len(figures))]),
        },
    )
    theta = np.clip(res.x, lo, hi)
    ll1 = -nll(theta)
    if ll1 < ll0:
        theta, ll1 = theta0, ll0
    # observed information: central differences of -ln L in theta
    h = 0.02
    k = len(figures)
    H = np.empty((k, k))
    f0 = -ll1
    for i in range(k):
        for j in range(i, k):
            ei, ej = np.eye(k)[i] * h, np.eye(k)[j] * h
            if i == j:
                H[i, i] = (nll(theta + ei) - 2 * f0 + nll(theta - ei)) / h**2
            else:
                H[i, j] = H[j, i] = (
                    nll(theta + ei + ej) - nll(theta + ei - ej) - nll(theta - ei + ej) + nll(theta - ei - ej)
                ) / (4 * h**2)
    # covariance on the well-determined directions; a figure that leans on a flat or curved-the-wrong-way
    # direction of -ln L (eigenvalue <= 0) gets no interval
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
    est = dict(start)
    est.update(values(theta))
    ci = {}
    for f in figures:
        if not math.isfinite(se[f]):
            ci[f] = (float("nan"), float("nan"))
        elif _is_c2(f):
            se[f] *= C2_SCALE
            ci[f] = (est[f] - 1.96 * se[f], est[f] + 1.96 * se[f])
        else:
            ci[f] = (est[f] * math.exp(-min(1.96 * se[f], 700.0)), est[f] * math.exp(min(1.96 * se[f], 700.0)))
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
        converged=bool(res.success),
        at_bound=tuple(f for f, t, a, b in zip(figures, theta, lo, hi, strict=True) if t <= a + 0.05 or t >= b - 0.05),
    )
