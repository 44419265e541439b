"""Whiteness tests: Ljung-Box against statsmodels, the ACF band, Bartlett's cumulative periodogram."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.tsa.stattools import acf as sm_acf

from accelnav.identify.whiteness import (
    acf,
    acf_band_test,
    cumulative_periodogram,
    cumulative_periodogram_test,
    ljung_box,
    whiteness,
)


def ar1(n: int, phi: float, seed: int, mean: float = 0.0) -> np.ndarray:
    e = np.random.default_rng(seed).standard_normal(n)
    x = np.empty(n)
    x[0] = e[0]
    for k in range(1, n):
        x[k] = phi * x[k - 1] + e[k]
    return x + mean


SERIES = [
    ("white, even n", lambda: ar1(4000, 0.0, 1)),
    ("white, odd n, large mean", lambda: ar1(3001, 0.0, 2, mean=-9.81)),
    ("AR(1) 0.1", lambda: ar1(5000, 0.1, 3)),
    ("AR(1) -0.3", lambda: ar1(777, -0.3, 4)),
]


@pytest.mark.parametrize("name,make", SERIES, ids=[s[0] for s in SERIES])
@pytest.mark.parametrize("lags", [1, 10, 20, 40])
def test_ljung_box_matches_statsmodels(name, make, lags):
    x = make()
    ours = ljung_box(x, lags)
    ref = acorr_ljungbox(x, lags=[lags], return_df=True)
    Q, p = float(ref["lb_stat"].iloc[0]), float(ref["lb_pvalue"].iloc[0])
    assert ours.statistic == pytest.approx(Q, rel=1e-9)
    if p > 1e-300:
        assert ours.p_value == pytest.approx(p, rel=1e-9)
    assert ours.white == (p >= 0.05)


def test_acf_matches_statsmodels():
    x = ar1(3001, 0.4, 5, mean=3.0)
    np.testing.assert_allclose(acf(x, 60), sm_acf(x, nlags=60, fft=False), rtol=0, atol=1e-13)


def test_cumulative_periodogram_statistic_is_a_kolmogorov_smirnov_test():
    # Under white noise the normalised cumulative periodogram U_1..U_q are ordered uniforms, so the
    # statistic and p-value must be scipy's one-sample KS test of U against U(0, 1).
    x = ar1(2001, 0.0, 6)
    f, U = cumulative_periodogram(x)
    res = cumulative_periodogram_test(x)
    ks = stats.kstest(U, "uniform", method="exact")
    assert res.statistic == pytest.approx(ks.statistic, rel=1e-12)
    assert res.p_value == pytest.approx(ks.pvalue, rel=1e-6)
    # the periodogram is taken at the Fourier frequencies 1/n .. (m-1)/n
    assert len(U) == (2001 - 1) // 2 - 1 and f[0] == pytest.approx(1 / 2001)
    assert np.all(np.diff(U) >= 0) and 0 < U[0] and U[-1] < 1


def test_acf_band_counts_lags_outside():
    n = 400
    rho = np.zeros(101)
    rho[0] = 1.0
    rho[[3, 50, 77]] = 0.5  # three lags far outside +-1.96/sqrt(400) = +-0.098
    rho[10] = 0.09  # inside
    res = acf_band_test(np.zeros(n), 100, rho=rho)
    assert res.statistic == pytest.approx(0.97)
    assert res.p_value == pytest.approx(stats.binom.sf(2, 100, 0.05))
    assert res.white  # 3 outside of 100 is what white noise does
    rho[1:21] = 0.3  # twenty more: not white
    res = acf_band_test(np.zeros(n), 100, rho=rho)
    assert not res.white and "NOT white" in res.verdict


def test_size_on_white_noise():
    # On white noise each test rejects at about its level (0.05); the ACF band test is conservative
    # (a discrete binomial count). 400 seeded series of 1000 samples; sd of a 0.05 rate is 0.011.
    rejections = np.zeros(3)
    runs = 400
    for seed in range(runs):
        w = whiteness(np.random.default_rng(100 + seed).standard_normal(1000))
        rejections += [not t.white for t in w.tests]
    rate = rejections / runs
    assert 0.02 <= rate[0] <= 0.09, f"Ljung-Box rejects {rate[0]:.3f}"
    assert 0.0 <= rate[1] <= 0.09, f"ACF band rejects {rate[1]:.3f}"
    assert 0.02 <= rate[2] <= 0.09, f"cumulative periodogram rejects {rate[2]:.3f}"


def test_power_on_correlated_noise():
    # AR(1) with phi = 0.2 over 3000 samples: rho_1 = 0.2 is 11 standard errors from zero, so
    # Ljung-Box and Bartlett reject every time. The band test counts lags outside among 100 and
    # barely notices two; it needs correlation that lasts (phi = 0.9: about 30 lags outside).
    verdicts = np.array([[t.white for t in whiteness(ar1(3000, 0.2, 200 + s)).tests] for s in range(30)])
    assert not verdicts[:, 0].any() and not verdicts[:, 2].any()
    long = np.array([[t.white for t in whiteness(ar1(3000, 0.9, 300 + s)).tests] for s in range(10)])
    assert not long.any()


def test_report_lines():
    w = whiteness(ar1(2000, 0.0, 9))
    assert w.acf[0] == pytest.approx(1.0) and len(w.acf) == 101
    assert w.band == pytest.approx(1.959963984540054 / np.sqrt(2000))
    for t in w.tests:
        assert t.verdict.startswith("white" if t.white else "NOT white")
        assert t.name in t.line() and f"{t.p_value:.3g}" in t.line()
    with pytest.raises(ValueError, match="constant"):
        whiteness(np.ones(100))
