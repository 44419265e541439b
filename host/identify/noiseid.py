"""Noise identification from a stationary recording: Allan deviation, its terms, the filter's noise figures.

Allan deviation
---------------
The overlapping Allan deviation comes from accelnav.identify.allan, the estimator
of allantools' ``oadev`` on the samples as "frequency" data, so the result is in
the samples' own units, m/s^2. Its 95 % confidence interval uses the equivalent degrees of freedom
of Greenhall (allantools' ``edf_greenhall``) for the noise type read from the
local log-log slope mu of the curve (alpha = -2 mu - 1, rounded into -2 .. 0:
white, flicker and random-walk rate noise).

Terms
-----
The Allan variance of independent noise processes adds, and each classic
term has its own power of tau (IEEE Std 952 annex C, IEEE Std 1293):

    white noise        sigma^2 = N^2 / tau         (N: read at tau = 1 s)
    flicker (bias instability)  sigma^2 = (2 ln 2 / pi) B^2
    random walk        sigma^2 = K^2 tau / 3
    drift (ramp)       sigma^2 = D^2 tau^2 / 2

N, B, K and D come from one non-negative least-squares fit of this sum to
the Allan variance, each point weighted by its relative uncertainty
sqrt(2 / edf), over tau >= min(1 s, tau_min / 10) (and at least 10 sample
periods). Shorter tau see the sensor's own bandwidth limit: a one-pole
output filter of bandwidth B leaves the Allan variance short of the white
line by about 1.5 tau_c / tau (tau_c = 1 / (2 pi B)), 24 % at 0.1 s for
B = 10 Hz, 2 % at 1 s; so N is, as the standard says, the white line at
tau = 1 s rather than the shortest-tau value. Beside the fit, the conventional read-outs: the minimum of the
curve (``adev_min`` at ``tau_min``, among the points with at least 10
equivalent degrees of freedom: the last few points of a curve scatter by a
factor of two) and B = adev_min / 0.664. When the fitted
random walk does not dominate the longest averaging times, K is replaced by
an upper bound: the largest K whose line K sqrt(tau/3) stays below the upper
95 % limit of every point (``K_is_bound``).

Units: for samples in m/s^2, N is in m/s^2/sqrt(Hz) with the two-sided
convention (white noise of two-sided density N^2 has Allan deviation
N/sqrt(tau)); a datasheet's one-sided density (rms^2 = density^2 x bandwidth)
is sqrt(2) N (``density_one_sided``). K is in m/s^2 sqrt(Hz) = m/s^2.5, B in
m/s^2, D in m/s^3.

Mapping to the filter (period Ts of the filter, not of the recording)
----------------------------------------------------------------------
* R, the variance of one acceleration sample: white noise of Allan
  coefficient N sampled every Ts has variance N^2 / Ts, so R = N^2 / Ts. This
  is the white-equivalent level in the band the filter averages over; the raw
  sample variance (``sample_var``) is reported beside it and is smaller when
  the sensor's bandwidth is below Nyquist.
* sigma_eps, the bias random walk (Q[3,3] = Ts sigma_eps^2, i.e. the bias
  wanders with variance sigma_eps^2 t): sigma_eps = K, the random-walk term,
  or its upper bound when the curve shows no random walk. Flicker noise has
  no exact random-walk equivalent; the bound keeps the filter from trusting
  the bias more than the data allow.
* sigma_n, the white-jerk intensity driving the vehicle's acceleration
  (Q[2,2] = Ts sigma_n^2), describes motion; a stationary recording contains
  none, so it cannot identify sigma_n (at most it shows that the sensor
  itself contributes far less). accelnav keeps the model's sigma_n and
  reports the paper's rule beside it:

      sigma_n^2 (paper) = variance of the derivative of the stationary signal,
      dy/dt ~ diff(y) / Ts,  deriv_var = var(diff(y)) / Ts^2  [(m/s^3)^2].

  Read as an intensity on the filter's grid (Q[2,2] = Ts sigma_n^2 equal to
  the variance of one step of y), that is sigma_n = sqrt(deriv_var * Ts) =
  sqrt(var(diff(y)) / Ts), the number ``sigma_n_paper``. For white noise of
  variance s^2 it is sqrt(2 s^2 / Ts).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from accelnav.identify import allan
from accelnav.lazy import lazy_module

optimize = lazy_module("scipy.optimize")


FLICKER_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)  # 0.664: sigma_min = 0.664 B
TAUS_PER_DECADE = 8
MAX_M_FRACTION = 0.25  # longest tau = a quarter of the record (Stable32's stop ratio for oadev)
FIT_MIN_SAMPLES = 10  # the term fit uses tau >= 10 sample periods ...
FIT_START_S = 1.0  # ... and starts at 1 s unless the curve bottoms out before 10 s
CI = 0.95
MIN_EDF_FOR_MIN = 10.0  # the Allan minimum is read only where the point has this many degrees of freedom


@dataclass(frozen=True, eq=False)
class AllanCurve:
    """Overlapping Allan deviation with its 95 % confidence interval."""

    tau: np.ndarray  # s
    adev: np.ndarray  # units of the samples
    lo: np.ndarray
    hi: np.ndarray
    edf: np.ndarray
    alpha: np.ndarray  # noise type used for the edf (power of f in the sample PSD)


@dataclass(frozen=True)
class NoiseTerms:
    """Classic Allan terms (see the module notes for definitions and units)."""

    N: float
    B: float  # conventional: adev_min / 0.664
    K: float  # random walk: fitted, or an upper bound if K_is_bound
    K_is_bound: bool
    K_fit: float
    K_bound: float
    B_fit: float
    D: float
    adev_min: float
    adev_min_ci: tuple[float, float]
    tau_min: float
    fit_tau_range: tuple[float, float]

    @property
    def density_one_sided(self) -> float:
        """Datasheet-style noise density, sqrt(2) N (rms^2 = density^2 x bandwidth)."""
        return math.sqrt(2.0) * self.N


@dataclass(frozen=True, eq=False)
class NoiseId:
    """Allan curve, its terms, the paper's rule and the mapping to the filter's R and sigma_eps."""

    curve: AllanCurve
    terms: NoiseTerms
    Ts: float  # sample period of the recording
    sample_var: float
    deriv_var: float  # var(diff(y)) / Ts^2, the paper's sigma_n^2
    sigma_n_paper: float  # sqrt(deriv_var * Ts)

    def R(self, Ts_filter: float | None = None) -> float:
        """Variance of one acceleration sample at the filter's period: N^2 / Ts."""
        return self.terms.N**2 / (self.Ts if Ts_filter is None else Ts_filter)

    @property
    def sigma_eps(self) -> float:
        return self.terms.K


def allan_deviation(y, rate_hz: float, *, taus_per_decade: int = TAUS_PER_DECADE, progress=None) -> AllanCurve:
    """Overlapping Allan deviation of samples ``y`` at ``rate_hz`` with 95 % intervals.

    Averaging factors m are log-spaced from 1 to a quarter of the record.
    ``progress`` (a :class:`accelnav.progress.Progress`, or None) has its ``total`` set to the number
    of taus and is advanced as they are computed.
    """
    y = np.asarray(y, dtype=np.float64)
    n = len(y)
    m_max = int(n * MAX_M_FRACTION)
    if m_max < 4:
        raise ValueError(f"{n} samples are too few for an Allan deviation")
    k = max(int(math.ceil(taus_per_decade * math.log10(m_max))) + 1, 4)
    ms = np.unique(np.round(np.geomspace(1, m_max, k)).astype(np.int64))
    taus = ms / rate_hz
    if progress is not None:
        progress.total = len(ms)
    x = allan.phase(y, rate_hz)
    dev = np.empty(len(ms))
    for i, m in enumerate(ms):
        dev[i], _ = allan.oadev_phase(x, rate_hz, int(m))
        if progress is not None:
            progress.update(i + 1)
    alpha = _noise_alpha(taus, dev)
    edf = np.array([_edf(int(a), int(m), n + 1) for a, m in zip(alpha, ms, strict=True)])
    lo = np.empty(len(ms))
    hi = np.empty(len(ms))
    for i in range(len(ms)):
        lo[i], hi[i] = allan.confidence_interval(dev[i], edf[i], CI)
    return AllanCurve(tau=taus, adev=dev, lo=lo, hi=hi, edf=edf, alpha=alpha)


def _noise_alpha(tau: np.ndarray, dev: np.ndarray) -> np.ndarray:
    """Power-law noise type per tau from the local slope mu: alpha = -2 mu - 1, rounded into -2 .. 0.

    Only the rate-noise types of inertial sensors are allowed (white 0, flicker -1, random walk -2):
    at long tau the local slope is noisy, and reading a steep chance slope as white phase noise
    (alpha = 1) would claim several times the degrees of freedom the point has.
    """
    lt, ld = np.log(tau), np.log(np.maximum(dev, 1e-300))
    if len(tau) < 3:
        return np.zeros(len(tau), dtype=int)
    mu = np.gradient(ld, lt)
    # smooth the noisy local slope over five neighbours
    mu = np.convolve(np.pad(mu, 2, mode="edge"), np.ones(5) / 5, mode="valid")
    return np.clip(np.round(-2.0 * mu - 1.0), -2, 0).astype(int)


def _edf(alpha: int, m: int, n_phase: int) -> float:
    try:
        edf = allan.edf_greenhall(alpha, m, n_phase)
    except (ZeroDivisionError, ValueError):
        edf = float("nan")
    if not math.isfinite(edf) or edf <= 0:
        edf = allan.edf_simple(n_phase - 1, m, alpha)
    return max(edf, 1.0)


def allan_terms(curve: AllanCurve, Ts: float) -> NoiseTerms:
    """Fit N, B, K, D to the curve and read its minimum; see the module notes."""
    tau, dev = curve.tau, curve.adev
    # the minimum is read where the point is well estimated (edf >= MIN_EDF_FOR_MIN)
    ok = curve.edf >= MIN_EDF_FOR_MIN
    if not ok.any():
        ok = np.ones(len(dev), dtype=bool)
    i_min = int(np.flatnonzero(ok)[np.argmin(dev[ok])])
    tau_start = max(FIT_MIN_SAMPLES * Ts, min(FIT_START_S, tau[i_min] / 10.0))
    use = tau >= tau_start * (1 - 1e-9)
    if use.sum() < 6:
        use = np.zeros(len(tau), dtype=bool)
        use[-min(6, len(tau)) :] = True
    tu, var = tau[use], dev[use] ** 2
    powers = (-1.0, 0.0, 1.0, 2.0)
    X = np.column_stack([tu**p for p in powers])
    coef_scale = np.array([1.0, FLICKER_FACTOR**2, 1.0 / 3.0, 0.5])  # var = sum coef_scale * term^2 * tau^p
    w = np.sqrt(curve.edf[use] / 2.0) / var
    A = X * coef_scale * w[:, None]
    col = np.linalg.norm(A, axis=0)
    sol, _ = optimize.nnls(A / col, var * w)
    sq = sol / col  # squared term coefficients
    N, B_fit, K_fit, D = (float(math.sqrt(max(s, 0.0))) for s in sq)

    # K from the fit only if the random walk carries most of the variance at the longest tau
    t_end = tu[-1]
    model_end = float(np.sum(coef_scale * sq * t_end ** np.array(powers)))
    rw_end = K_fit**2 * t_end / 3.0
    K_bound = float(np.min(curve.hi * np.sqrt(3.0 / tau)))
    K_seen = model_end > 0 and rw_end > 0.5 * model_end
    return NoiseTerms(
        N=N,
        B=float(dev[i_min] / FLICKER_FACTOR),
        K=K_fit if K_seen else K_bound,
        K_is_bound=not K_seen,
        K_fit=K_fit,
        K_bound=K_bound,
        B_fit=B_fit,
        D=D,
        adev_min=float(dev[i_min]),
        adev_min_ci=(float(curve.lo[i_min]), float(curve.hi[i_min])),
        tau_min=float(tau[i_min]),
        fit_tau_range=(float(tu[0]), float(tu[-1])),
    )


def derivative_variance(y, Ts: float) -> float:
    """The paper's sigma_n^2: variance of the sample derivative diff(y) / Ts, in (units/s)^2."""
    d = np.diff(np.asarray(y, dtype=np.float64))
    return float(np.var(d) / (Ts * Ts))


def identify_noise(y, rate_hz: float, *, taus_per_decade: int = TAUS_PER_DECADE, progress=None) -> NoiseId:
    """Allan curve and terms of ``y`` (residuals of the bias fit), the paper's rule, sample variance."""
    y = np.asarray(y, dtype=np.float64)
    Ts = 1.0 / rate_hz
    curve = allan_deviation(y, rate_hz, taus_per_decade=taus_per_decade, progress=progress)
    terms = allan_terms(curve, Ts)
    dv = derivative_variance(y, Ts)
    return NoiseId(
        curve=curve,
        terms=terms,
        Ts=Ts,
        sample_var=float(np.var(y)),
        deriv_var=dv,
        sigma_n_paper=math.sqrt(dv * Ts),
    )
