"""Are the residuals of the bias fit white? Three tests, each with a verdict.

* **Ljung-Box**: Q = n (n + 2) sum_{k=1..h} rho_k^2 / (n - k), compared with
  chi-square with h - model_df degrees of freedom (model_df = 0 here: the
  fitted bias parameters are not ARMA terms). rho_k is the sample
  autocorrelation with the mean removed and the lag-0 sum in the denominator,
  the definition statsmodels' ``acf`` uses.
* **ACF band**: the fraction of rho_1 .. rho_K inside +-1.96/sqrt(n). For white
  noise each lag falls outside with probability 0.05, so the count outside is
  about Binomial(K, 0.05); the p-value is P(count >= observed). This is the
  weakest of the three against a correlation that dies out in a few lags (two
  lags outside among a hundred is what white noise does too) and the one that
  sees a correlation lasting many lags.
* **Cumulative periodogram** (Bartlett): with I_j the periodogram at the
  Fourier frequencies j = 1 .. m (m = floor((n - 1) / 2)), the normalised
  partial sums U_j = sum_{i<=j} I_i / sum_{i<=m} I_i, j = 1 .. m - 1, are for
  white noise the order statistics of m - 1 uniform variables; the
  Kolmogorov-Smirnov distance from the diagonal and its exact p-value
  (scipy's ``kstwo``) make the test.

Each test reports white when its p-value is at least ``alpha`` (0.05). On
long records (1e6 samples) these tests see correlations far too small to
matter to the filter; the report gives the size of the largest |rho_k| so the
reader can judge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from accelnav.lazy import lazy_module

fft = lazy_module("scipy.fft")
stats = lazy_module("scipy.stats")


DEFAULT_LB_LAGS = 20
DEFAULT_ACF_LAGS = 100
ALPHA = 0.05


@dataclass(frozen=True)
class TestResult:
    """One whiteness test: its statistic, p-value and verdict at level ``alpha``."""

    name: str
    statistic: float
    p_value: float
    alpha: float
    detail: str  # what the statistic is, in words and numbers

    __test__ = False  # not a pytest class

    @property
    def white(self) -> bool:
        return bool(self.p_value >= self.alpha)

    @property
    def verdict(self) -> str:
        word = "white" if self.white else "NOT white"
        rel = ">=" if self.white else "<"
        return f"{word} (p = {self.p_value:.3g} {rel} {self.alpha:g})"

    def line(self) -> str:
        return f"{self.name}: {self.detail}; {self.verdict}"


@dataclass(frozen=True, eq=False)
class Whiteness:
    """The three tests on one residual series, and what the plots need."""

    n: int
    acf: np.ndarray  # rho_0 .. rho_K
    band: float  # 1.96 / sqrt(n)
    ljung_box: TestResult
    acf_band: TestResult
    cumulative_periodogram: TestResult
    cp_freq: np.ndarray  # (m - 1,) frequencies of U_j, in cycles per sample
    cp_U: np.ndarray  # (m - 1,) the normalised cumulative periodogram
    cp_critical: float  # 95 % Kolmogorov-Smirnov distance for m - 1 points

    @property
    def tests(self) -> tuple[TestResult, TestResult, TestResult]:
        return (self.ljung_box, self.acf_band, self.cumulative_periodogram)

    @property
    def white(self) -> bool:
        return all(t.white for t in self.tests)


def acf(x, nlags: int) -> np.ndarray:
    """Sample autocorrelation rho_0 .. rho_nlags (mean removed, biased: divided by n c_0)."""
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    if nlags >= n:
        raise ValueError(f"nlags = {nlags} must be below the series length {n}")
    xc = x - x.mean()
    size = fft.next_fast_len(n + nlags + 1, real=True)
    X = fft.rfft(xc, size)
    acov = fft.irfft(X.real**2 + X.imag**2, size)[: nlags + 1]
    if not acov[0] > 0:
        raise ValueError("the series is constant; its autocorrelation is undefined")
    return acov / acov[0]


def ljung_box(x, lags: int = DEFAULT_LB_LAGS, model_df: int = 0, alpha: float = ALPHA, *, rho=None) -> TestResult:
    """Ljung-Box portmanteau test of the first ``lags`` autocorrelations (``rho`` may be given)."""
    n = len(x)
    if not 0 < lags < n:
        raise ValueError(f"lags = {lags} must be in 1 .. {n - 1}")
    if lags - model_df < 1:
        raise ValueError(f"lags - model_df = {lags - model_df} leaves no degrees of freedom")
    r = acf(x, lags) if rho is None else np.asarray(rho)
    k = np.arange(1, lags + 1)
    Q = float(n * (n + 2) * np.sum(r[1 : lags + 1] ** 2 / (n - k)))
    p = float(stats.chi2.sf(Q, lags - model_df))
    worst = int(np.argmax(np.abs(r[1 : lags + 1]))) + 1
    detail = f"Q({lags}) = {Q:.4g}, largest |rho| = {abs(r[worst]):.3g} at lag {worst}"
    return TestResult("Ljung-Box", Q, p, alpha, detail)


def acf_band_test(x, nlags: int = DEFAULT_ACF_LAGS, alpha: float = ALPHA, *, rho=None) -> TestResult:
    """Fraction of rho_1 .. rho_nlags inside +-1.96/sqrt(n), with a binomial p-value on the count outside."""
    n = len(x)
    r = acf(x, nlags) if rho is None else np.asarray(rho)
    band = 1.959963984540054 / np.sqrt(n)
    outside = int(np.sum(np.abs(r[1 : nlags + 1]) > band))
    inside = 1.0 - outside / nlags
    p = float(stats.binom.sf(outside - 1, nlags, 0.05))
    detail = (
        f"{100 * inside:.1f} % of lags 1..{nlags} inside +-1.96/sqrt(n) "
        f"({outside} outside, ~{0.05 * nlags:.0f} expected)"
    )
    return TestResult("ACF band", inside, p, alpha, detail)


def cumulative_periodogram(x) -> tuple[np.ndarray, np.ndarray]:
    """(frequency in cycles/sample, U_j) of the normalised cumulative periodogram, j = 1 .. m - 1."""
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    m = (n - 1) // 2
    if m < 3:
        raise ValueError(f"{n} samples are too few for a cumulative periodogram")
    X = fft.rfft(x - x.mean())[1 : m + 1]
    I = X.real**2 + X.imag**2
    S = np.cumsum(I)
    if not S[-1] > 0:
        raise ValueError("the series is constant; its periodogram is zero")
    U = S[:-1] / S[-1]
    f = np.arange(1, m) / n
    return f, U


def cumulative_periodogram_test(x, alpha: float = ALPHA, *, curve=None) -> TestResult:
    """Bartlett's test: Kolmogorov-Smirnov distance of the cumulative periodogram from the diagonal."""
    f, U = cumulative_periodogram(x) if curve is None else curve
    q = len(U)
    j = np.arange(1, q + 1)
    D = float(max(np.max(j / q - U), np.max(U - (j - 1) / q)))
    p = float(stats.kstwo.sf(D, q))
    detail = f"KS distance {D:.4g} over {q} frequencies (95 % critical {stats.kstwo.isf(0.05, q):.3g})"
    return TestResult("cumulative periodogram", D, p, alpha, detail)


def whiteness(
    x, *, lb_lags: int = DEFAULT_LB_LAGS, acf_lags: int = DEFAULT_ACF_LAGS, alpha: float = ALPHA
) -> Whiteness:
    """All three tests on the series ``x`` (typically the residuals of the bias fit)."""
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    acf_lags = min(acf_lags, n // 4)
    lb_lags = min(lb_lags, n // 5)
    if acf_lags < 1 or lb_lags < 1:
        raise ValueError(f"{n} samples are too few for whiteness tests")
    rho = acf(x, max(acf_lags, lb_lags))
    curve = cumulative_periodogram(x)
    q = len(curve[1])
    return Whiteness(
        n=n,
        acf=rho,
        band=1.959963984540054 / np.sqrt(n),
        ljung_box=ljung_box(x, lb_lags, alpha=alpha, rho=rho),
        acf_band=acf_band_test(x, acf_lags, alpha=alpha, rho=rho),
        cumulative_periodogram=cumulative_periodogram_test(x, alpha, curve=curve),
        cp_freq=curve[0],
        cp_U=curve[1],
        cp_critical=float(stats.kstwo.isf(0.05, q)),
    )
