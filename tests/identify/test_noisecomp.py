"""Composite noise model: recovery of simulated mixtures, and the band check against the filter's noise model.

Stated tolerances (seeded; measured worst over the seeds below in brackets in the commit that set them):
white N within 2 %, random walk K within 30 %, GM sigma within 20 %, GM correlation time within a factor 1.7
(the Allan variance locates a GM hump only loosely when white noise of similar level lies on top of it).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from accelnav.identify.noisecomp import (
    WARN_RATIO,
    check_band,
    filter_avar,
    fit_composite,
    gm_avar_shape,
)
from accelnav.identify.noiseid import allan_deviation, allan_terms


def simulate(n: int, fs: float, N: float, gms, K: float, seed: int) -> np.ndarray:
    """White (Allan N^2/tau) + first-order GM terms (sigma, T), exactly discretised + random walk K."""
    rng = np.random.default_rng(seed)
    Ts = 1.0 / fs
    y = rng.standard_normal(n) * N / math.sqrt(Ts)
    for s, T in gms:
        phi = math.exp(-Ts / T)
        e = rng.standard_normal(n) * s * math.sqrt(1 - phi**2)
        e[0] = s * rng.standard_normal()
        y += signal.lfilter([1.0], [1.0, -phi], e)
    y += np.cumsum(rng.standard_normal(n)) * K * math.sqrt(Ts)
    return y


def test_gm_shape_limits():
    u = np.array([1e-6, 1e-4, 1e-3 * (1 - 1e-12), 1e-3, 1.0, 1e4])
    g = gm_avar_shape(u)
    # the two branches agree at the switch, and the limits are random walk (2u/3) and white (2/u)
    assert g[2] == pytest.approx(g[3], rel=1e-8)
    assert g[0] == pytest.approx(2e-6 / 3, rel=1e-5)
    assert g[-1] == pytest.approx(2.0 / 1e4, rel=1e-3)
    # direct form of the textbook expression at u = 1
    assert g[4] == pytest.approx(2.0 * (1 - 0.5 * (3 - 4 * math.exp(-1) + math.exp(-2))), rel=1e-12)


def test_gm_shape_matches_allantools_on_a_simulated_gm():
    fs, T = 100.0, 1.0
    y = simulate(400_000, fs, 0.0, [(1.0, T)], 0.0, 5)
    c = allan_deviation(y, fs)
    ok = (c.edf > 100) & (c.tau >= 0.05)
    ratio = c.adev[ok] ** 2 / gm_avar_shape(c.tau[ok] / T)
    assert np.all(np.abs(ratio - 1) < 0.1), ratio


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_recovers_white_gm_random_walk(seed):
    fs, N, K, s, T = 100.0, 0.0098, 3e-4, 0.004, 2.0
    y = simulate(1_000_000, fs, N, [(s, T)], K, seed)
    comp = fit_composite(allan_deviation(y, fs), 1 / fs)
    assert comp.N == pytest.approx(N, rel=0.02)
    assert comp.K == pytest.approx(K, rel=0.30)
    assert len(comp.gm) == 1
    assert comp.gm[0].sigma == pytest.approx(s, rel=0.20)
    assert 1 / 1.7 < comp.gm[0].T / T < 1.7
    assert not comp.fit_poor


@pytest.mark.parametrize("seed", [0, 1])
def test_no_gm_term_invented_on_white_plus_random_walk(seed):
    fs, N, K = 100.0, 0.01, 3e-4
    y = simulate(500_000, fs, N, [], K, seed)
    comp = fit_composite(allan_deviation(y, fs), 1 / fs)
    assert comp.N == pytest.approx(N, rel=0.02)
    assert comp.K == pytest.approx(K, rel=0.30)
    # a GM term may be kept only if it is negligible against the white noise where it acts
    assert all(g.N_equiv < 0.2 * N for g in comp.gm), comp.gm


def _phone_like(seed: int):
    """The issue's phone: 10 Hz, 6 h, Allan deviation rising from ~3e-3 at 0.1 s to a hump of ~4-5e-3 near 3 s."""
    fs, N, s, T = 10.0, 8e-4, 7e-3, 1.5
    y = simulate(216_000, fs, N, [(s, T)], 0.0, seed)
    return fs, y, N**2 + 2 * s**2 * T  # true white-equivalent level at tau >> T


@pytest.mark.parametrize("seed", [0, 1])
def test_band_limited_signal_warns_and_the_band_R_covers_it(seed):
    fs, y, n2_true = _phone_like(seed)
    c = allan_deviation(y, fs)
    i = int(np.argmax(c.adev))
    assert c.adev[i] > 1.3 * c.adev[0] and 1.0 < c.tau[i] < 6.0  # the curve rises to a hump, like the phone's
    terms = allan_terms(c, 1 / fs)
    R_white = terms.N**2 * fs  # what fit-bias wrote before: the white line at tau = 1 s
    comp = fit_composite(c, 1 / fs)
    chk = check_band(c, comp, R=R_white, Ts_filter=1 / fs, sigma_eps=terms.K, T_bias=1e4)
    assert chk.understated and chk.worst_ratio > 3 * WARN_RATIO
    # the truth says how much the white R understates the band's upper end (100 s, ~ the GM's white asymptote)
    true_ratio = n2_true * (1 - 1.5 * 1.5 / 100) / terms.N**2
    assert chk.worst_ratio == pytest.approx(true_ratio, rel=0.25)
    # the band's R: the filter's curve then covers the true noise over the band, without a gross excess
    true_avar = 8e-4**2 / chk.tau + 7e-3**2 * gm_avar_shape(chk.tau / 1.5)
    filt = filter_avar(chk.tau, chk.R_chosen, 1 / fs, terms.K, 1e4)
    assert np.all(filt > 0.8 * true_avar)
    assert chk.R_chosen < 1.5 * n2_true * fs


@pytest.mark.parametrize("seed", [0, 1])
def test_white_noise_is_not_flagged(seed):
    fs = 10.0
    y = simulate(216_000, fs, 3e-3, [], 1e-5, seed)
    c = allan_deviation(y, fs)
    terms = allan_terms(c, 1 / fs)
    comp = fit_composite(c, 1 / fs)
    chk = check_band(c, comp, R=terms.N**2 * fs, Ts_filter=1 / fs, sigma_eps=terms.K, T_bias=1e4)
    assert not chk.understated and chk.reference == "composite"
    assert chk.R_chosen == chk.R_white


def test_a_filter_with_too_small_R_is_flagged_even_for_white_noise():
    # the check compares against the filter's model, not against the fit's own N
    fs = 10.0
    y = simulate(100_000, fs, 3e-3, [], 0.0, 3)
    c = allan_deviation(y, fs)
    comp = fit_composite(c, 1 / fs)
    chk = check_band(c, comp, R=(3e-3) ** 2 * fs / 4, Ts_filter=1 / fs, sigma_eps=1e-6, T_bias=1e4)
    assert chk.understated and chk.worst_ratio == pytest.approx(4.0, rel=0.15)
    assert chk.R_band == pytest.approx((3e-3) ** 2 * fs, rel=0.15)


def test_band_outside_the_curve_is_refused():
    fs = 10.0
    c = allan_deviation(simulate(20_000, fs, 3e-3, [], 0.0, 1), fs)
    comp = fit_composite(c, 1 / fs)
    with pytest.raises(ValueError, match="does not overlap"):
        check_band(c, comp, R=1e-4, Ts_filter=0.1, sigma_eps=0.0, T_bias=100.0, band=(5000.0, 9000.0))
