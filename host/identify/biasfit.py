"""Bias identification: fit eps(t) = c1 (1 - exp(-t/T)) + c2 to a stationary recording.

The fit is nonlinear only in T. For a fixed decay rate lam = 1/T the model

    y[k] = b0 + b1 e[k] + v[k],    e[k] = exp(-lam t[k]),    b0 = c1 + c2,  b1 = -c1

is a straight-line regression on e, so c1 and c2 have a closed form and the
residual sum of squares RSS(T) is a function of T alone (the *profile*). The
fit is therefore a one-dimensional search over log T on a dense grid, a
bounded Brent refinement around the best grid point, and one exact pass over
the data at the optimum that gives residuals, the Jacobian and the standard
errors (with Gauss-Newton polish steps if that pass finds the optimum off).

Fast profile on long records
----------------------------
RSS(T) needs only three sums: sum e, sum e^2 and sum y e. They are evaluated
without touching the samples again: the first ``HEAD`` samples are summed
exactly, the rest are split into blocks whose length grows geometrically
(each block is ``BLOCK_GROWTH`` times the time since the first sample), and
inside a block centred on c with half-width h

    sum_k y[k] exp(-lam t[k]) = exp(-lam c) sum_j (-lam h)^j / j! M_j,
    M_j = sum_k y[k] u[k]^j,   u[k] = (t[k] - c) / h  in [-1, 1].

With growth 0.25 and ``N_MOMENTS`` = 15 terms the truncation error is below
3e-15 of one sample's term for every lam (the worst case, lam t ~ 15, gives
(lam t / 8)^15 exp(-lam t) / 15!). So a record of 1e7 samples reduces once to
about 50 blocks x 15 moments and every later RSS(T) costs microseconds,
which is what makes a dense grid over six decades of T affordable.

Uncertainty
-----------
``se`` and ``ci95`` are the classical nonlinear least-squares ones,
covariance s^2 (J^T J)^-1 with s^2 = RSS / (n - 3), widened for short-range
correlation of the residual: s^2 is multiplied by ``srf`` = 1 + 2 sum_k
(1 - k/(K+1)) rho_k over a Bartlett window of K = ceil(4 (n/100)^(2/9)) lags
(the Newey-West choice). Because the regressors (1 and the exponential) vary
slowly compared with K samples, this scalar factor is what the Newey-West
sandwich reduces to; it is about 1 for white residuals and corrects, for
example, the lag-1 correlation a sensor's own output filter leaves. The 95 %
interval of c1 and c2 is Wald (estimate +- 1.96 se); the interval of T is the
profile-likelihood interval {T : RSS(T) - RSS_min <= 3.84 s^2 srf}, which
follows the asymmetry of T better than a Wald interval.

Correlation longer than the window (flicker noise, a wandering bias) makes
even these intervals too narrow: ``vif``, the long-run variance inflation of
the residual from 32 batch means (1 for white residuals), says by how much
the variances should grow; ``ci95_lr`` are the intervals widened by
max(1, vif, srf), and the identification decision below uses that factor.

Identification of T
-------------------
T counts as identified when (1) the best T is inside the searched range,
(2) the 95 % profile interval of T, with its threshold scaled by max(1, vif, srf),
closes on both sides inside that range, (3) the exact pass converged, and
(4) the 95 % interval of c1, widened the same way, excludes zero (with T
free, a small c1 can close the profile of T by chance). A
profile open above means the data show a drift that is not seen to level off
(c1 and T are then confounded: only c1/T is known); open below means no
warm-up longer than a few samples. Otherwise the fit falls back to a constant
bias (c1 = 0, c2 = mean) and says so in ``verdict``.

Time origin: t = 0 is the first sample of the recording, so c2 is the bias at
the start of the recording (at power-on only if the recording starts there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from accelnav.lazy import lazy_module

optimize = lazy_module("scipy.optimize")


HEAD = 1024  # samples summed exactly at every T
BLOCK_GROWTH = 0.25  # block length / time of the block's start
N_MOMENTS = 15  # Taylor terms j = 0 .. 14 per block
GRID_PER_DECADE = 24  # profile grid density in log T
T_MIN_SAMPLES = 10.0  # default lower end of the T search, in sample periods
T_MAX_DURATIONS = 10.0  # default upper end of the T search, in record durations
CHUNK = 1 << 16  # samples per piece in the passes over the data
MIN_SAMPLES = 64  # fewer samples than this cannot support a three-parameter fit
VIF_BATCHES = 32  # batches for the long-run variance of the residual
Z95 = 1.959963984540054  # two-sided 95 % normal quantile
CHI2_1_95 = 3.841458820694124  # 95 % quantile of chi-square with one degree of freedom

PARAMS = ("c1", "c2", "T")


class FitError(ValueError):
    """Data the fit cannot use; ``str()`` is one line."""


@dataclass(frozen=True, eq=False)
class ExpFit:
    """The three-parameter fit, whether or not T turned out to be identified.

    Tuples are ordered as ``PARAMS`` = (c1, c2, T). ``T_grid`` and
    ``rss_grid`` are the profile RSS(T) on the search grid (for plots).
    """

    c1: float
    c2: float
    T: float
    cov: np.ndarray  # (3, 3) covariance of (c1, c2, T), widened by srf
    se: tuple[float, float, float]
    ci95: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    T_ci_closed: tuple[bool, bool]  # the profile interval of T closed (below, above) inside the range
    ci95_lr: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]  # allowing for vif
    rss: float
    sigma: float
    converged: bool
    T_range: tuple[float, float]
    T_grid: np.ndarray
    rss_grid: np.ndarray


@dataclass(frozen=True, eq=False)
class BiasFit:
    """Result of :func:`fit_bias`, in the units of ``y`` and seconds.

    When T is identified, (c1, c2, T) are the exponential fit; otherwise the
    bias is constant: c1 = 0, c2 = mean of y, T = nan (``exp`` still holds
    the rejected exponential fit for the report). ``se`` and ``ci95`` are
    ordered (c1, c2, T) and allow for short-range residual correlation
    (``srf``, see the module notes); ``ci95_lr`` are the same intervals
    widened for the residual's long-run variance (variances times
    max(1, vif, srf) instead of srf); entries that do not apply are nan.
    ``residuals`` = y - eps_hat(t).
    """

    c1: float
    c2: float
    T: float
    se: tuple[float, float, float]
    ci95: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    ci95_lr: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    T_identified: bool
    verdict: str
    vif: float
    srf: float
    sigma: float
    n: int
    t0: float
    duration: float
    residuals: np.ndarray
    exp: ExpFit

    def predict(self, t) -> np.ndarray:
        """eps_hat at absolute times ``t`` (the same clock as the fitted samples)."""
        t = np.asarray(t, dtype=np.float64) - self.t0
        if not self.T_identified:
            return np.full_like(t, self.c2)
        return -self.c1 * np.expm1(-t / self.T) + self.c2

    def interval(self, name: str) -> tuple[float, float]:
        return self.ci95[PARAMS.index(name)]

    def stderr(self, name: str) -> float:
        return self.se[PARAMS.index(name)]

    def why_truth_outside(self, name: str, truth: float, white: bool) -> str:
        """'' when the 95 % interval of ``name`` holds ``truth`` (a simulation's); else why not, from this fit's
        own evidence (``white``: did the residuals pass the whiteness tests): the constant-bias fallback, the
        residuals' long-run correlation (the widened interval holds it), a wandering bias, or, with white
        residuals, the one miss in twenty that a 95 % interval allows."""
        i = PARAMS.index(name)
        lo, hi = self.ci95[i]
        if lo <= truth <= hi:
            return ""
        if not self.T_identified:
            return (
                "T was not identified, so the fit fell back to a constant bias (c1 = 0, c2 = the mean): the model "
                "it fitted is not the one that made the data"
            )
        lo_lr, hi_lr = self.ci95_lr[i]
        if lo_lr <= truth <= hi_lr:
            return (
                f"the residuals are correlated (long-run variance x{self.vif:.3g}): the interval widened for that, "
                f"[{lo_lr:.4g}, {hi_lr:.4g}], holds it"
            )
        if not white:
            return (
                f"outside the widened [{lo_lr:.4g}, {hi_lr:.4g}] too: the residuals are not white, the bias wanders "
                "(random walk sigma_eps), and the fit finds this recording's path, not the model's mean curve"
            )
        return "the residuals are white and no cause is seen: a 95 % interval misses the truth in 1 fit of 20"


# --------------------------------------------------------------------------
# Profile sums


class ProfileSums:
    """sum e, sum e^2 and sum y e for e = exp(-lam t), at any lam, from one pass over the data.

    ``t`` must start at 0 and increase; ``y`` should be centred (its mean
    removed) so that the profile RSS does not cancel against a large constant.
    """

    def __init__(self, t: np.ndarray, y: np.ndarray):
        n = len(t)
        k0 = min(n, HEAD)
        self.n = n
        self.t_head = t[:k0]
        self.y_head = y[:k0]
        self.sy = float(np.sum(y))
        self.syy = _dot(y, y)
        starts, centres, halves, m1, my = [], [], [], [], []
        if k0 < n:
            edge = float(t[k0])
            edges = [edge]
            while edges[-1] <= t[-1]:
                edges.append(edges[-1] * (1.0 + BLOCK_GROWTH))
            bounds = np.searchsorted(t, edges, side="left")
            for i in range(len(edges) - 1):
                a, b = int(bounds[i]), int(bounds[i + 1])
                if b <= a:
                    continue
                c = 0.5 * (edges[i] + edges[i + 1])
                h = 0.5 * (edges[i + 1] - edges[i])
                mom1 = np.zeros(N_MOMENTS)
                momy = np.zeros(N_MOMENTS)
                for s0 in range(a, b, CHUNK):  # pieces that stay in cache through the 15 powers
                    s1 = min(s0 + CHUNK, b)
                    u = (t[s0:s1] - c) / h
                    p1 = np.ones_like(u)
                    py = y[s0:s1].copy()
                    for j in range(N_MOMENTS):
                        mom1[j] += p1.sum()
                        momy[j] += py.sum()
                        if j + 1 < N_MOMENTS:
                            p1 *= u
                            py *= u
                starts.append(edges[i])
                centres.append(c)
                halves.append(h)
                m1.append(mom1)
                my.append(momy)
        self.start = np.array(starts)
        self.centre = np.array(centres)
        self.half = np.array(halves)
        self.m1 = np.array(m1).reshape(-1, N_MOMENTS)
        self.my = np.array(my).reshape(-1, N_MOMENTS)
        self._inv_fact = 1.0 / np.array([math.factorial(j) for j in range(N_MOMENTS)])

    def _blocks(self, lam: np.ndarray, moments: np.ndarray) -> np.ndarray:
        if len(self.centre) == 0:
            return np.zeros_like(lam)
        x = lam[:, None]
        live = x * self.start[None, :] < 700.0  # beyond this the block's terms underflow anyway
        coef = moments * self._inv_fact  # (B, J): M_j / j!
        with np.errstate(over="ignore", under="ignore", invalid="ignore"):
            z = -x * self.half[None, :]  # (L, B)
            series = np.broadcast_to(coef[:, -1], z.shape)
            for j in range(N_MOMENTS - 2, -1, -1):  # Horner: sum_j coef_j z^j
                series = series * z + coef[:, j]
            terms = np.where(live, np.exp(-x * self.centre[None, :]) * series, 0.0)
        return terms.sum(axis=1)

    def sums(self, lam) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sum e, sum e^2, sum y e) for each decay rate in ``lam``."""
        lam = np.atleast_1d(np.asarray(lam, dtype=np.float64))
        E = np.exp(-np.outer(lam, self.t_head))
        s1 = E.sum(axis=1) + self._blocks(lam, self.m1)
        s2 = (E * E).sum(axis=1) + self._blocks(2.0 * lam, self.m1)
        sy = np.einsum("lk,k->l", E, self.y_head) + self._blocks(lam, self.my)
        return s1, s2, sy

    def profile(self, lam) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(RSS, b0, b1) of y = b0 + b1 exp(-lam t) for each lam (b0 relative to the centred y)."""
        s1, s2, sey = self.sums(lam)
        n = self.n
        see = s2 - s1 * s1 / n
        sey = sey - s1 * self.sy / n
        with np.errstate(divide="ignore", invalid="ignore"):
            b1 = np.where(see > 0, sey / see, 0.0)
            rss = self.syy - self.sy**2 / n - np.where(see > 0, sey * sey / see, 0.0)
        b0 = (self.sy - b1 * s1) / n
        return np.maximum(rss, 0.0), b0, b1


def profile_rss_exact(t: np.ndarray, y: np.ndarray, T: float) -> float:
    """RSS of the best (c1, c2) at fixed T, computed directly from every sample (for tests)."""
    g = -np.expm1(-(t - t[0]) / T)
    A = np.column_stack([g, np.ones_like(g)])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ coef
    return float(r @ r)


# --------------------------------------------------------------------------
# The fit


def _check(t: np.ndarray, y: np.ndarray) -> None:
    if t.ndim != 1 or y.ndim != 1 or len(t) != len(y):
        raise FitError(f"t and y must be 1-D arrays of one length, got shapes {t.shape} and {y.shape}")
    n = len(t)
    if n < MIN_SAMPLES:
        raise FitError(f"only {n} samples; the bias fit needs at least {MIN_SAMPLES}")
    bad = ~np.isfinite(y)
    if bad.any():
        k = int(np.argmax(bad))
        raise FitError(f"{int(bad.sum())} samples are not finite, the first at sample {k} (t = {t[k]:.6g} s)")
    if not np.isfinite(t).all():
        k = int(np.argmax(~np.isfinite(t)))
        raise FitError(f"time is not finite at sample {k}")
    dt = np.diff(t)
    if (dt <= 0).any():
        k = int(np.argmax(dt <= 0))
        raise FitError(f"time does not increase at sample {k + 1} ({t[k]:.6g} s -> {t[k + 1]:.6g} s)")
    if np.ptp(y) == 0:
        raise FitError(f"the signal is constant ({y[0]:.6g} in every sample); nothing to fit")


def _vif(r: np.ndarray, sigma2: float) -> float:
    """Long-run variance inflation of the residual from batch means: 1 for white noise."""
    L = len(r) // VIF_BATCHES
    if L < 2 or sigma2 <= 0:
        return 1.0
    means = r[: L * VIF_BATCHES].reshape(VIF_BATCHES, L).mean(axis=1)
    return float(L * np.sum(means * means) / (VIF_BATCHES - 1) / sigma2)


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Inner product without BLAS: OpenBLAS threads its dot above 10 000 elements, and on a busy
    machine waking those threads for every piece costs several times the arithmetic."""
    return float(np.einsum("i,i->", a, b))


def _srf(r: np.ndarray) -> float:
    """Short-range variance factor 1 + 2 sum_k (1 - k/(K+1)) rho_k (Bartlett window, Newey-West K)."""
    n = len(r)
    K = min(int(math.ceil(4.0 * (n / 100.0) ** (2.0 / 9.0))), n // 4)
    if K < 1:
        return 1.0
    mean = float(np.mean(r))
    lags = np.zeros(K + 1)
    step = 1 << 18
    for s0 in range(0, n, step):  # every lag of one piece while it is in cache
        seg = r[s0 : min(s0 + step + K, n)] - mean
        m = min(step, n - s0)
        for k in range(K + 1):
            mk = min(m, len(seg) - k)
            lags[k] += _dot(seg[:mk], seg[k : k + mk])
    if lags[0] <= 0:
        return 1.0
    k = np.arange(1, K + 1)
    return max(1.0 + 2.0 * float(np.sum((1.0 - k / (K + 1.0)) * lags[1:])) / lags[0], 0.25)


def _cov_from_normal(A: np.ndarray, sigma2: float) -> np.ndarray:
    """sigma2 (J^T J)^-1, inverted after scaling to unit diagonal."""
    d = np.sqrt(np.diag(A))
    if not np.all(d > 0):
        return np.full((3, 3), np.inf)
    try:
        inv = np.linalg.inv(A / np.outer(d, d)) / np.outer(d, d)
    except np.linalg.LinAlgError:
        return np.full((3, 3), np.inf)
    return sigma2 * inv


def _exact_pass(t, y, c1, c2, T, r_out: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """One pass over every sample at (c1, c2, T): (J^T J, J^T r, RSS); the residuals go to ``r_out``.

    Model c1 g + c2 with g = 1 - exp(-t/T); Jacobian columns [g, 1, -c1 t exp(-t/T) / T^2].
    Computed in cache-sized pieces, with no N x 3 matrix.
    """
    A = np.zeros((3, 3))
    b = np.zeros(3)
    rss = 0.0
    k = -c1 / (T * T)
    for s0 in range(0, len(t), CHUNK):
        tt = t[s0 : s0 + CHUNK]
        e = np.exp(-tt / T)
        g = 1.0 - e
        h = k * tt * e
        r = r_out[s0 : s0 + CHUNK]
        np.subtract(y[s0 : s0 + CHUNK], c1 * g + c2, out=r)
        sg, sh = g.sum(), h.sum()
        gg, gh, hh = _dot(g, g), _dot(g, h), _dot(h, h)
        A += np.array([[gg, sg, gh], [sg, len(tt), sh], [gh, sh, hh]])
        b += np.array([_dot(g, r), r.sum(), _dot(h, r)])
        rss += _dot(r, r)
    return A, b, rss


def _polish(tr, y, c1, c2, T_hat, T_range):
    """Gauss-Newton from the profile's optimum on the exact residuals, each step kept inside ``T_range`` and
    only if it lowers the RSS (halved otherwise): (c1, c2, T, normal matrix, RSS, residuals, converged)."""
    n, dof = len(tr), len(tr) - 3
    T_lo, T_hi = T_range
    converged = False
    r = np.empty(n)
    spare = np.empty(n)
    A, b, rss = _exact_pass(tr, y, c1, c2, T_hat, r)
    for _ in range(8):
        sigma2 = rss / dof
        cov = _cov_from_normal(A, sigma2)
        se = np.sqrt(np.abs(np.diag(cov)))
        if not (np.all(np.isfinite(se)) and sigma2 > 0):
            break
        step = cov @ b / sigma2  # Gauss-Newton: (J^T J)^-1 J^T r
        if np.all(np.abs(step) <= 1e-4 * se):
            converged = True
            break
        # take the step only inside the searched range and only if it lowers the RSS; halve it otherwise
        for _half in range(30):
            new_T = T_hat + step[2]
            if T_lo <= new_T <= T_hi:
                new_c1, new_c2 = c1 + step[0], c2 + step[1]
                new_A, new_b, new_rss = _exact_pass(tr, y, new_c1, new_c2, new_T, spare)
                if new_rss <= rss:
                    c1, c2, T_hat, A, b, rss = new_c1, new_c2, new_T, new_A, new_b, new_rss
                    r, spare = spare, r
                    break
            step = step / 2
        else:
            break
    return c1, c2, T_hat, A, rss, r, converged


def _verdict(*, at_lo, at_hi, converged, closed_lr, c1, c1_ci_lr, T_ci, T_range, duration, inflate) -> str:
    """Why T is or is not identified, in one sentence (it starts "T identified" only when it is)."""
    T_lo, T_hi = T_range
    if at_hi:
        return (
            f"T not identified: the best T is at the top of the search ({T_hi:.4g} s, "
            f"{T_hi / duration:.3g}x the record); the data show a drift that does not level off"
        )
    if at_lo:
        return (
            f"T not identified: the best T is at the bottom of the search ({T_lo:.4g} s); "
            f"no warm-up longer than a few samples"
        )
    if not converged:
        return "T not identified: the three-parameter fit did not converge (c1 and T are confounded)"
    if not all(closed_lr):
        side = "above" if not closed_lr[1] else "below"
        why = (
            "the warm-up is not seen to level off; only c1/T is determined"
            if side == "above"
            else "a much faster warm-up fits as well"
        )
        return (
            f"T not identified: its 95 % profile interval is open {side} within [{T_lo:.4g}, {T_hi:.4g}] s "
            f"(allowing for residual correlation: variances x {inflate:.3g}); {why}"
        )
    if c1_ci_lr[0] <= 0.0 <= c1_ci_lr[1]:
        return (
            f"T not identified: c1 = {c1:.4g} is not distinguishable from zero (95 % interval "
            f"[{c1_ci_lr[0]:.4g}, {c1_ci_lr[1]:.4g}] allowing for residual correlation): no visible warm-up"
        )
    return (
        f"T identified: 95 % profile interval [{T_ci[0]:.4g}, {T_ci[1]:.4g}] s "
        f"inside the search range [{T_lo:.4g}, {T_hi:.4g}] s"
    )


def fit_bias(
    t,
    y,
    *,
    T_min: float | None = None,
    T_max: float | None = None,
    progress=None,
    level_bound: float = 0.0,
) -> BiasFit:
    """Fit eps(t) = c1 (1 - exp(-(t - t[0])/T)) + c2 to the stationary samples ``y`` at times ``t``.

    ``T_min`` / ``T_max`` bound the search (default: 10 sample periods and 10
    record durations). ``level_bound``: how far the samples' mean may sit from the
    signal's whatever their number (a read-out step that hides the noise:
    :mod:`accelnav.identify.quantised`); the intervals of c2 (a level) grow by it and
    those of c1 (two levels' difference) by twice it, and c1 must clear zero by
    those to identify T. ``progress`` (a :class:`accelnav.progress.Progress` over
    4 stages, or None) is advanced as the stages finish. Raises
    :class:`FitError` for data it cannot use (too few samples, non-finite
    values, time not increasing, a constant signal).
    """
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    _check(t, y)
    n = len(t)
    t0 = float(t[0])
    tr = t - t0
    duration = float(tr[-1])
    dt = duration / (n - 1)
    T_lo = T_MIN_SAMPLES * dt if T_min is None else float(T_min)
    T_hi = T_MAX_DURATIONS * duration if T_max is None else float(T_max)
    if not 0 < T_lo < T_hi:
        raise FitError(f"the T search range [{T_lo:g}, {T_hi:g}] s is empty")
    ybar = float(np.mean(y))
    yc = y - ybar

    # 1. sufficient statistics of the profile
    sums = ProfileSums(tr, yc)
    _advance(progress, 1)

    # 2. profile RSS(T) on a log grid, then Brent around the best point
    n_grid = max(int(math.ceil(GRID_PER_DECADE * math.log10(T_hi / T_lo))) + 1, 8)
    T_grid = np.geomspace(T_lo, T_hi, n_grid)
    rss_grid = sums.profile(1.0 / T_grid)[0]
    i = int(np.argmin(rss_grid))
    lo, hi = math.log(T_grid[max(i - 1, 0)]), math.log(T_grid[min(i + 1, n_grid - 1)])

    def prof(logT: float) -> float:
        return float(sums.profile(np.array([math.exp(-logT)]))[0][0])

    res = optimize.minimize_scalar(prof, bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
    logT = float(res.x) if res.fun <= rss_grid[i] else math.log(T_grid[i])
    T_hat = math.exp(logT)
    rss_prof, b0, b1 = (float(v[0]) for v in sums.profile(np.array([1.0 / T_hat])))
    c1 = -b1
    c2 = ybar + b0 + b1
    _advance(progress, 2)

    # 3. exact pass at the optimum: residuals, Jacobian, Gauss-Newton polish if needed
    dof = n - 3
    c1, c2, T_hat, A, rss, r, converged = _polish(tr, y, c1, c2, T_hat, (T_lo, T_hi))
    c1, c2, T_hat = float(c1), float(c2), float(T_hat)
    _advance(progress, 3)

    # 4. intervals, correlation factors, identification
    sigma2 = rss / dof
    vif = _vif(r, sigma2)
    srf = _srf(r)
    cov = _cov_from_normal(A, sigma2) * srf
    se = np.sqrt(np.abs(np.diag(cov)))
    z = Z95
    w1, w2 = 2 * level_bound, level_bound
    ci_c1 = (float(c1 - z * se[0] - w1), float(c1 + z * se[0] + w1))
    ci_c2 = (float(c2 - z * se[1] - w2), float(c2 + z * se[1] + w2))
    rss_min = min(rss, rss_prof)
    (T_ci, closed) = _profile_interval(prof, T_grid, rss_grid, T_hat, rss_min, CHI2_1_95 * sigma2 * srf)
    inflate = max(1.0, vif, srf)
    (T_ci_lr, closed_lr) = _profile_interval(prof, T_grid, rss_grid, T_hat, rss_min, CHI2_1_95 * sigma2 * inflate)
    zl = Z95 * math.sqrt(inflate / srf)
    ci95_lr = (
        (float(c1 - zl * se[0] - w1), float(c1 + zl * se[0] + w1)),
        (float(c2 - zl * se[1] - w2), float(c2 + zl * se[1] + w2)),
        T_ci_lr,
    )
    if level_bound > 0:  # every T the bound leaves open, with its c1 and c2
        hull, span1, span2 = _level_hull(sums, T_grid, ybar, duration, (c1, c2, T_hat), level_bound)
        T_ci, closed = _joined(T_ci, closed, hull)
        T_ci_lr, closed_lr = _joined(ci95_lr[2], closed_lr, hull)
        ci_c1, ci_c2 = _spanned(ci_c1, span1, w1), _spanned(ci_c2, span2, w2)
        ci95_lr = (_spanned(ci95_lr[0], span1, w1), _spanned(ci95_lr[1], span2, w2), T_ci_lr)
    exp_fit = ExpFit(
        c1=float(c1),
        c2=float(c2),
        T=float(T_hat),
        cov=_readonly(cov),
        se=(float(se[0]), float(se[1]), float(se[2])),
        ci95=(ci_c1, ci_c2, T_ci),
        T_ci_closed=closed,
        ci95_lr=ci95_lr,
        rss=rss,
        sigma=math.sqrt(sigma2),
        converged=converged,
        T_range=(T_lo, T_hi),
        T_grid=_readonly(T_grid),
        rss_grid=_readonly(rss_grid),
    )

    verdict = _verdict(
        at_lo=i == 0,
        at_hi=i == n_grid - 1,
        converged=converged,
        closed_lr=closed_lr,
        c1=c1,
        c1_ci_lr=ci95_lr[0],
        T_ci=T_ci,
        T_range=(T_lo, T_hi),
        duration=duration,
        inflate=inflate,
    )
    identified = verdict.startswith("T identified")
    _advance(progress, 4)

    if identified:
        return BiasFit(
            c1=float(c1),
            c2=float(c2),
            T=float(T_hat),
            se=exp_fit.se,
            ci95=exp_fit.ci95,
            ci95_lr=exp_fit.ci95_lr,
            T_identified=True,
            verdict=verdict,
            vif=vif,
            srf=srf,
            sigma=math.sqrt(sigma2),
            n=n,
            t0=t0,
            duration=duration,
            residuals=_readonly(r),
            exp=exp_fit,
        )
    # constant bias
    r0 = yc
    s0 = _dot(r0, r0) / (n - 1)
    srf0 = _srf(r0)
    se_c2 = math.sqrt(s0 * srf0 / n)
    nan = math.nan
    vif0 = _vif(r0, s0)
    se_lr = se_c2 * math.sqrt(max(1.0, vif0, srf0) / srf0)
    return BiasFit(
        c1=0.0,
        c2=ybar,
        T=nan,
        se=(nan, se_c2, nan),
        ci95=((nan, nan), (ybar - Z95 * se_c2 - w2, ybar + Z95 * se_c2 + w2), (nan, nan)),
        ci95_lr=((nan, nan), (ybar - Z95 * se_lr - w2, ybar + Z95 * se_lr + w2), (nan, nan)),
        T_identified=False,
        verdict=verdict + "; falling back to a constant bias (c1 = 0, c2 = mean)",
        vif=vif0,
        srf=srf0,
        sigma=math.sqrt(s0),
        n=n,
        t0=t0,
        duration=duration,
        residuals=_readonly(r0),
        exp=exp_fit,
    )


def _level_hull(sums, T_grid, ybar, duration, best, bound):
    """The T of the grid whose best curve stays within +-2 ``bound`` of the best fit's over the record: T the
    samples cannot tell apart when their mean is known to +-bound only (each curve may be off the signal by
    bound, as c1's interval allows). Returns ((lo, hi, closed below, closed above), (c1 range), (c2 range)):
    the outermost such T, one grid point further out, whether that is inside the grid, and the best c1, c2
    over those T."""
    c1, c2, T_hat = best
    _, b0, b1 = sums.profile(1.0 / T_grid)
    tt = np.unique(np.concatenate([np.linspace(0.0, duration, 400), np.geomspace(duration * 1e-6, duration, 400)]))
    fitted = c2 - c1 * np.expm1(-tt / T_hat)
    curves = ybar + b0[:, None] + b1[:, None] * np.exp(-tt[None, :] / T_grid[:, None])
    ok = np.nonzero(np.max(np.abs(curves - fitted[None, :]), axis=1) <= 2 * bound)[0]
    if len(ok) == 0:
        return (T_hat, T_hat, True, True), (c1, c1), (c2, c2)
    i, j = int(ok[0]), int(ok[-1])
    last = len(T_grid) - 1
    c1s, c2s = -b1[ok], ybar + b0[ok] + b1[ok]
    return (
        (float(T_grid[max(i - 1, 0)]), float(T_grid[min(j + 1, last)]), i > 0, j < last),
        (float(min(c1, c1s.min())), float(max(c1, c1s.max()))),
        (float(min(c2, c2s.min())), float(max(c2, c2s.max()))),
    )


def _joined(ci, closed, hull):
    """A profile interval of T grown to the level hull (:func:`_level_hull`)."""
    lo, hi, c_lo, c_hi = hull
    return (
        (min(ci[0], lo), max(ci[1], hi)),
        (closed[0] and (c_lo or ci[0] < lo), closed[1] and (c_hi or ci[1] > hi)),
    )


def _spanned(ci, span, w):
    """An interval grown to hold ``span`` widened by +-w."""
    return (float(min(ci[0], span[0] - w)), float(max(ci[1], span[1] + w)))


def _profile_interval(prof, T_grid, rss_grid, T_hat, rss_min, delta):
    """The 95 % profile interval of T: where RSS(T) - RSS_min <= delta, walking out from T_hat.

    Returns ((lo, hi), (closed_below, closed_above)); an open side reports the
    end of the search range.
    """
    level = rss_min + delta
    logs = np.log(T_grid)
    lt = math.log(T_hat)

    def f(logT: float) -> float:
        return prof(logT) - level

    ends = []
    closed = []
    for direction in (-1, +1):
        idx = np.nonzero(logs < lt)[0][::-1] if direction < 0 else np.nonzero(logs > lt)[0]
        inner = lt
        found = None
        if f(inner) >= 0:  # the optimum itself is at the level (degenerate profile): a zero-width side
            ends.append(T_hat)
            closed.append(True)
            continue
        for k in idx:
            if rss_grid[k] > level:
                found = float(optimize.brentq(f, min(inner, logs[k]), max(inner, logs[k]), xtol=1e-12))
                break
            inner = logs[k]
        if found is None:
            ends.append(float(T_grid[0] if direction < 0 else T_grid[-1]))
            closed.append(False)
        else:
            ends.append(math.exp(found))
            closed.append(True)
    return (ends[0], ends[1]), (closed[0], closed[1])


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    a.flags.writeable = False
    return a


def _advance(progress, stage: int) -> None:
    if progress is not None:
        progress.update(stage)
