"""Composite noise model fitted to the Allan variance, and its check against the filter's own noise model.

Terms
-----
The Allan variance of independent processes adds. Beside the classic terms of
:mod:`accelnav.identify.noiseid` (white N^2/tau, flicker (2 ln 2/pi) B^2,
random walk K^2 tau/3, drift D^2 tau^2/2) the composite model carries up to
``MAX_GM`` first-order Gauss-Markov (band-limited) terms. A GM process of
stationary variance s^2 and correlation time T (x' = -x/T + w) has

    sigma_A^2(tau) = s^2 g(tau/T),   g(u) = (2/u) (1 - v/u - v^2/(2u)),   v = 1 - exp(-u)

(the usual (2 s^2 T/tau)[1 - (T/2tau)(3 - 4e^-u + e^-2u)], rewritten to
avoid cancellation; g(u) ~ 2u/3 for u << 1, a random walk of K^2 = 2 s^2/T,
and g(u) ~ 2/u for u >> 1, white noise of N^2 = 2 s^2 T). Low-pass filtered
white noise is such a process: this is what a band-limited sensor output, or
the "hump" of an Allan curve that rises before it falls, looks like.

Fit (in the manner of GMWM: the model's Allan variance against the empirical one, not line slopes read by
eye): for fixed correlation times the Allan variance is linear in the squared amplitudes, so those come from a
non-negative least-squares fit of the relative misfit, each point weighted by sqrt(edf/2) (the relative
standard deviation of an Allan variance estimate with edf degrees of freedom), reweighted twice with the model
in the denominator. The correlation times are searched on a log grid inside the curve's tau range (a GM term
with T outside [2 tau_first, tau_last/2] cannot be told from white noise or a random walk there) and refined
by Nelder-Mead on log T. White noise and random walk are always in the model; flicker and drift (which compete
with the random walk and slow GM terms) and 0, 1 or 2 GM terms are each kept only where seen: of all these
candidates the one with the least chi^2 + ``BIC_PER_PARAM`` ln(n) x (number of parameters) wins (BIC; the
points overlap, so the chi^2 is a quality figure, not an exact likelihood). Fit quality is stated as the
weighted chi^2 per point and the share of points whose model value lies outside the empirical 95 % interval.

The check that matters for the filter
-------------------------------------
The filter assumes a measurement noise that is white with variance R per
sample (Allan variance R Ts / tau) plus a bias that is a Gauss-Markov
process of time constant T (the axis's T) driven by sigma_eps (stationary
variance sigma_eps^2 T / 2). Its implied Allan variance is therefore

    avar_filter(tau) = R Ts / tau + sigma_eps^2 T / 2 * g(tau / T)

Position error is driven by the low-frequency part of the noise, over the
averaging times between one aid (rest, fix) and the next: the *band*
[tau_lo, tau_hi] (default 0.1 s .. 100 s, clipped to the curve). The check is
the largest ratio composite / avar_filter over the band: the factor by which
the filter understates the noise variance there. Above ``WARN_RATIO`` the
white-noise R misrepresents that band, and the band's R is the smallest R
for which the filter's curve covers the composite over the whole band:

    R_band = max over the band of (avar_composite(tau) - bias part(tau)) tau / Ts

When the composite itself misses the empirical curve inside the band (more
than ``POOR_FIT_SHARE`` of the band's points outside their 95 % interval),
the check says so and uses the empirical curve (its points with at least 10
degrees of freedom) instead of the composite.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from accelnav.identify.noiseid import FLICKER_FACTOR, MIN_EDF_FOR_MIN, AllanCurve
from accelnav.lazy import lazy_module

optimize = lazy_module("scipy.optimize")

MAX_GM = 2
GRID_PER_DECADE = 4
# chi^2 drop needed per added parameter, in units of ln(n). Overlapping Allan points at 8 per decade are
# strongly correlated, so the chi^2 counts each piece of evidence several times: 1 (plain BIC) kept a spurious
# GM term on white + random walk in 2 of 2 seeds, 4 in none, while real GM terms drop the chi^2 by 100s.
BIC_PER_PARAM = 4.0
WARN_RATIO = 1.5  # composite / filter variance above this anywhere in the band: the white R misrepresents it
POOR_FIT_SHARE = 0.2  # share of points outside their 95 % interval above which the fit is called poor
DEFAULT_BAND_S = (0.1, 100.0)
FIT_MIN_SAMPLES = 5  # shortest tau used, in sample periods (shorter ones see the sample grid itself)


def gm_avar_shape(u) -> np.ndarray:
    """g(u): Allan variance of a unit-variance first-order Gauss-Markov process at tau = u T."""
    u = np.asarray(u, dtype=np.float64)
    out = np.empty_like(u)
    small = u < 1e-3
    us = u[small]
    out[small] = us * (2.0 / 3.0 + us * (-0.5 + us * 7.0 / 30.0))  # series, relative error ~u^3
    ul = u[~small]
    v = -np.expm1(-ul)
    out[~small] = (2.0 / ul) * (1.0 - v / ul - v * v / (2.0 * ul))
    return out


@dataclass(frozen=True)
class GaussMarkov:
    sigma: float  # stationary standard deviation, units of the samples
    T: float  # correlation time, s

    @property
    def N_equiv(self) -> float:
        """White-noise level it looks like at tau >> T: sqrt(2 s^2 T)."""
        return math.sqrt(2.0 * self.sigma**2 * self.T)

    @property
    def K_equiv(self) -> float:
        """Random-walk level it looks like at tau << T: sqrt(2 s^2 / T)."""
        return math.sqrt(2.0 * self.sigma**2 / self.T)


@dataclass(frozen=True, eq=False)
class Composite:
    """Composite noise model fitted to an Allan curve."""

    N: float  # white, m/s^2/sqrt(Hz) (Allan N^2/tau)
    B: float  # flicker (bias instability), m/s^2
    K: float  # random walk, m/s^2/sqrt(s)
    D: float  # drift, m/s^3
    gm: tuple[GaussMarkov, ...]
    chi2: float  # weighted chi^2 of the relative misfit
    n_points: int
    outside_share: float  # share of the fitted points whose model value is outside the 95 % interval
    max_rel_err: float  # max |model/empirical - 1| of the Allan deviation over the fitted points
    tau_range: tuple[float, float]
    candidates: tuple[tuple[int, tuple[str, ...], float], ...]  # (GM terms, optional terms, chi^2) of each model tried

    def avar(self, tau, parts: bool = False):
        """Model Allan variance at ``tau`` (or a dict of its parts)."""
        tau = np.asarray(tau, dtype=np.float64)
        p = {
            "white": self.N**2 / tau,
            "flicker": np.full_like(tau, FLICKER_FACTOR**2 * self.B**2),
            "random walk": self.K**2 * tau / 3.0,
            "drift": self.D**2 * tau**2 / 2.0,
        }
        for i, g in enumerate(self.gm):
            p[f"GM{i + 1}"] = g.sigma**2 * gm_avar_shape(tau / g.T)
        return p if parts else sum(p.values())

    @property
    def fit_poor(self) -> bool:
        return self.outside_share > POOR_FIT_SHARE


OPTIONAL = ("flicker", "drift")  # kept only where seen (they compete with the random walk and GM terms)


def _columns(tau: np.ndarray, Ts: list[float], optional: tuple[str, ...]) -> np.ndarray:
    zero = np.zeros_like(tau)
    cols = [
        1.0 / tau,
        np.full_like(tau, FLICKER_FACTOR**2) if "flicker" in optional else zero,
        tau / 3.0,
        tau**2 / 2.0 if "drift" in optional else zero,
    ]
    cols += [gm_avar_shape(tau / T) for T in Ts]
    return np.column_stack(cols)


def _nnls(tau, avar, edf, Ts: list[float], optional: tuple[str, ...] = ()) -> tuple[np.ndarray, float]:
    """Squared amplitudes [N^2, B^2, K^2, D^2, s1^2, ...] and the weighted chi^2, for fixed GM times."""
    X = _columns(tau, Ts, optional)
    ref = avar.copy()
    sol = np.zeros(X.shape[1])
    for _ in range(3):  # the first pass weights by the data, the next two by the model
        w = np.sqrt(edf / 2.0) / ref
        A = X * w[:, None]
        col = np.linalg.norm(A, axis=0)
        col[col == 0] = 1.0
        s, _ = optimize.nnls(A / col, avar * w, maxiter=50 * X.shape[1])
        sol = s / col
        model = X @ sol
        ref = np.where(model > 0, model, avar)
    chi2 = float(np.sum((edf / 2.0) * ((X @ sol - avar) / ref) ** 2))
    return sol, chi2


def fit_composite(curve: AllanCurve, Ts: float, *, max_gm: int = MAX_GM) -> Composite:
    """Fit white + flicker + random walk + drift + up to ``max_gm`` GM terms to ``curve`` (see the module notes)."""
    use = curve.tau >= FIT_MIN_SAMPLES * Ts * (1 - 1e-9)
    tau, avar, edf = curve.tau[use], curve.adev[use] ** 2, curve.edf[use]
    if len(tau) < 8:
        raise ValueError(f"the Allan curve has {len(tau)} points at tau >= {FIT_MIN_SAMPLES} samples; need 8")
    lo, hi = 2.0 * tau[0], tau[-1] / 2.0
    n_grid = max(2, int(round(GRID_PER_DECADE * math.log10(hi / lo))) + 1)
    grid = np.geomspace(lo, hi, n_grid)
    n = len(tau)
    fits = []
    subsets = [(), ("flicker",), ("drift",), ("flicker", "drift")]
    for opt in subsets:
        for k in range(0, max_gm + 1):
            fits.append(_fit_k(tau, avar, edf, k, opt, grid, lo, hi))
    penalty = BIC_PER_PARAM * math.log(n)
    chosen = min(fits, key=lambda f: f[3] + penalty * (2 + len(f[4]) + 2 * f[0]))
    k, T, sol, chi2, _ = chosen
    gm = tuple(
        sorted(
            (GaussMarkov(math.sqrt(s), t) for s, t in zip(sol[4:], T, strict=True) if s > 0),
            key=lambda g: g.T,
        )
    )
    comp = Composite(
        N=math.sqrt(sol[0]),
        B=math.sqrt(sol[1]),
        K=math.sqrt(sol[2]),
        D=math.sqrt(sol[3]),
        gm=gm,
        chi2=chi2,
        n_points=n,
        outside_share=0.0,
        max_rel_err=0.0,
        tau_range=(float(tau[0]), float(tau[-1])),
        candidates=tuple((f[0], f[4], f[3]) for f in fits),
    )
    model_dev = np.sqrt(comp.avar(tau))
    outside = (model_dev < curve.lo[use]) | (model_dev > curve.hi[use])
    return Composite(
        **{
            **comp.__dict__,
            "outside_share": float(np.mean(outside)),
            "max_rel_err": float(np.max(np.abs(model_dev / curve.adev[use] - 1.0))),
        }
    )


def _fit_k(tau, avar, edf, k: int, opt: tuple[str, ...], grid, lo: float, hi: float):
    """Best fit with ``k`` GM terms and the optional terms ``opt``: (k, T list, solution, chi^2, opt)."""
    if k == 0:
        sol, chi2 = _nnls(tau, avar, edf, [], opt)
        return (0, [], sol, chi2, opt)
    best = None
    for Tc in itertools.combinations(grid, k):
        _, chi2 = _nnls(tau, avar, edf, list(Tc), opt)
        if best is None or chi2 < best[1]:
            best = (list(Tc), chi2)

    def cost(logT):
        return _nnls(tau, avar, edf, list(np.exp(np.clip(logT, math.log(lo), math.log(hi)))), opt)[1]

    res = optimize.minimize(cost, np.log(best[0]), method="Nelder-Mead", options={"xatol": 1e-3, "maxiter": 200})
    T = [float(t) for t in np.exp(np.clip(res.x, math.log(lo), math.log(hi)))]
    sol, chi2 = _nnls(tau, avar, edf, T, opt)
    if chi2 > best[1]:
        T = [float(t) for t in best[0]]
        sol, chi2 = _nnls(tau, avar, edf, T, opt)
    return (k, T, sol, chi2, opt)


def filter_avar(tau, R: float, Ts_filter: float, sigma_eps: float, T_bias: float) -> np.ndarray:
    """Allan variance the filter's noise model implies: white R plus the GM bias of time constant T_bias."""
    tau = np.asarray(tau, dtype=np.float64)
    return R * Ts_filter / tau + bias_avar(tau, sigma_eps, T_bias)


def bias_avar(tau, sigma_eps: float, T_bias: float) -> np.ndarray:
    tau = np.asarray(tau, dtype=np.float64)
    return sigma_eps**2 * T_bias / 2.0 * gm_avar_shape(tau / T_bias)


@dataclass(frozen=True, eq=False)
class BandCheck:
    """The filter's noise model against the composite (or the data) over the band that matters."""

    band: tuple[float, float]
    tau: np.ndarray  # points of the band at which it was checked
    ratio: np.ndarray  # reference / filter Allan variance at those points
    worst_ratio: float
    worst_tau: float
    R_white: float  # the white-noise R the check was made against
    R_band: float  # smallest R whose curve covers the reference over the band
    reference: str  # "composite" or "empirical" (when the composite fits the band poorly)
    band_outside_share: float  # share of the band's points outside their 95 % interval under the composite
    Ts_filter: float
    sigma_eps: float
    T_bias: float

    @property
    def understated(self) -> bool:
        return self.worst_ratio > WARN_RATIO

    @property
    def R_chosen(self) -> float:
        return self.R_band if self.understated else self.R_white


def check_band(
    curve: AllanCurve,
    comp: Composite,
    *,
    R: float,
    Ts_filter: float,
    sigma_eps: float,
    T_bias: float,
    band: tuple[float, float] = DEFAULT_BAND_S,
) -> BandCheck:
    """Compare the filter's implied Allan variance with the composite over ``band`` (see the module notes)."""
    lo, hi = band
    if not (0 < lo < hi):
        raise ValueError(f"noise band {lo:g} .. {hi:g} s: need 0 < low < high")
    good = curve.edf >= MIN_EDF_FOR_MIN
    tmax = float(curve.tau[good].max()) if good.any() else float(curve.tau[-1])
    lo_c, hi_c = max(lo, comp.tau_range[0]), min(hi, tmax)
    if hi_c <= lo_c:
        raise ValueError(
            f"noise band {lo:g} .. {hi:g} s does not overlap the Allan curve's reliable range "
            f"{comp.tau_range[0]:.3g} .. {tmax:.3g} s"
        )
    inb = (curve.tau >= lo_c * (1 - 1e-9)) & (curve.tau <= hi_c * (1 + 1e-9))
    model_dev = np.sqrt(comp.avar(curve.tau[inb]))
    outside = float(np.mean((model_dev < curve.lo[inb]) | (model_dev > curve.hi[inb]))) if inb.any() else 0.0
    if outside > POOR_FIT_SHARE:
        reference = "empirical"
        pts = inb & good
        tau = curve.tau[pts]
        ref = curve.adev[pts] ** 2
    else:
        reference = "composite"
        tau = np.geomspace(lo_c, hi_c, 64)
        ref = comp.avar(tau)
    ratio = ref / filter_avar(tau, R, Ts_filter, sigma_eps, T_bias)
    i = int(np.argmax(ratio))
    R_band = float(np.max((ref - bias_avar(tau, sigma_eps, T_bias)) * tau / Ts_filter))
    return BandCheck(
        band=(lo_c, hi_c),
        tau=tau,
        ratio=ratio,
        worst_ratio=float(ratio[i]),
        worst_tau=float(tau[i]),
        R_white=R,
        R_band=max(R_band, R),
        reference=reference,
        band_outside_share=outside,
        Ts_filter=Ts_filter,
        sigma_eps=sigma_eps,
        T_bias=T_bias,
    )
