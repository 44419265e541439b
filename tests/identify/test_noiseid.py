"""Noise identification: the Allan deviation and its intervals, the terms, the filter mapping."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from accelnav.hil_sim.sim.sensor import noise_sigma_rho, simulate
from accelnav.identify.noiseid import allan_deviation, derivative_variance, identify_noise
from accelnav.model.edit import revalidate
from accelnav.model.load import G0


def oadev_by_definition(y: np.ndarray, rate: float, m: int) -> float:
    """Overlapping Allan deviation from its definition (NIST SP 1065 eq. 11), phase x = integral of y."""
    Ts = 1.0 / rate
    x = np.concatenate([[0.0], np.cumsum(y - y.mean()) * Ts])
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    return math.sqrt(np.sum(d * d) / (2.0 * (m * Ts) ** 2 * len(d)))


def test_allan_deviation_is_the_overlapping_allan_deviation():
    rate = 50.0
    y = np.random.default_rng(0).standard_normal(5000) * 0.3 + 2.0
    c = allan_deviation(y, rate)
    assert c.tau[0] == pytest.approx(1 / rate) and c.tau[-1] == pytest.approx(1250 / rate)
    for tau, dev in zip(c.tau, c.adev, strict=True):
        m = int(round(tau * rate))
        assert dev == pytest.approx(oadev_by_definition(y, rate, m), rel=1e-9), m
    assert np.all(c.lo < c.adev) and np.all(c.adev < c.hi)


def test_allan_intervals_cover_95_percent():
    # White noise of sigma 1 at 100 Hz: sigma_A(tau) = 1 / sqrt(m). 200 seeded records of 4000
    # samples; at m = 4, 40 and 400 (edf about 1500, 140 and 10) the 95 % interval must cover the
    # truth in 88 to 99 % of them.
    ms = (4, 40, 400)
    hits = np.zeros(len(ms))
    runs = 200
    for seed in range(runs):
        c = allan_deviation(np.random.default_rng(seed).standard_normal(4000), 100.0)
        m_grid = np.round(c.tau * 100).astype(int)
        for j, m in enumerate(ms):
            i = int(np.argmin(np.abs(m_grid - m)))
            truth = 1.0 / math.sqrt(m_grid[i])
            hits[j] += c.lo[i] <= truth <= c.hi[i]
    frac = hits / runs
    assert np.all(frac >= 0.88) and np.all(frac <= 0.99), frac


def test_white_noise_terms_and_mapping():
    sigma, rate = 0.126, 100.0
    Ts = 1 / rate
    y = sigma * np.random.default_rng(1).standard_normal(200_000)
    nz = identify_noise(y, rate)
    k = nz.terms
    assert k.N == pytest.approx(sigma * math.sqrt(Ts), rel=0.03)
    assert k.K_is_bound  # no random walk in white noise: K is only bounded
    assert k.K == k.K_bound and k.K_bound < 0.1 * sigma * math.sqrt(Ts)
    # R is the variance of one sample at the filter's period: N^2 / Ts
    assert nz.R() == pytest.approx(sigma**2, rel=0.06)
    assert nz.R(0.02) == pytest.approx(k.N**2 / 0.02, rel=1e-12)
    assert nz.sample_var == pytest.approx(np.var(y), rel=1e-12)
    # paper's rule: var(dy/dt) = 2 sigma^2 / Ts^2 for white noise; sigma_n = sqrt(var * Ts)
    assert nz.deriv_var == pytest.approx(np.var(np.diff(y)) / Ts**2, rel=1e-12)
    assert nz.deriv_var == pytest.approx(2 * sigma**2 / Ts**2, rel=0.02)
    assert nz.sigma_n_paper == pytest.approx(math.sqrt(2 * sigma**2 / Ts), rel=0.01)
    assert k.density_one_sided == pytest.approx(math.sqrt(2) * k.N)


def test_random_walk_term():
    # white noise plus a random walk of intensity K: sigma_A^2 = N^2/tau + K^2 tau / 3
    rate, sigma, K = 100.0, 0.05, 2e-3
    rng = np.random.default_rng(2)
    n = 1_000_000
    y = sigma * rng.standard_normal(n) + np.cumsum(K * math.sqrt(1 / rate) * rng.standard_normal(n))
    nz = identify_noise(y, rate)
    assert not nz.terms.K_is_bound
    assert nz.terms.K == pytest.approx(K, rel=0.2)
    assert nz.sigma_eps == nz.terms.K
    assert nz.terms.N == pytest.approx(sigma * math.sqrt(1 / rate), rel=0.03)
    # the minimum sits where the two lines cross: N/sqrt(tau) = K sqrt(tau/3) -> tau = sqrt(3) N / K
    tau_cross = math.sqrt(3) * sigma * math.sqrt(1 / rate) / K
    assert tau_cross / 2 < nz.terms.tau_min < tau_cross * 2


def _variant(model, *, adc_bits: int, bandwidth_hz: float):
    an = dataclasses.replace(model.sensor.analog, adc_bits=adc_bits)
    sensor = dataclasses.replace(model.sensor, analog=an, bandwidth_hz=bandwidth_hz)
    noise = dataclasses.replace(model.noise, sigma_eps=0.0)
    return revalidate(dataclasses.replace(model, sensor=sensor, noise=noise))


def test_noise_density_from_the_simulator(default_model):
    # A 16-bit ADC (step far below the noise) and a 5 Hz output filter (well below Nyquist): the
    # Allan-derived one-sided density sqrt(2) N must be within 10 % of the model's datasheet density.
    model = _variant(default_model, adc_bits=16, bandwidth_hz=5.0)
    run = simulate(model, "stationary", 1000.0, 7, initial_random=False)
    nz = identify_noise(run.accel[:, 0], model.rate_hz)
    d = model.sensor.noise_density_g_rthz * G0
    assert nz.terms.density_one_sided == pytest.approx(d, rel=0.10)


def test_noise_density_with_the_output_filter_at_nyquist(default_model):
    # With the default 50 Hz one-pole filter at 100 Hz the noise above Nyquist folds back: the
    # sampled AR(1) noise has a low-frequency density of sigma sqrt(2 Ts (1 + rho) / (1 - rho)),
    # 1.31x the datasheet's. The Allan density must follow the sampled noise within 10 %.
    model = _variant(default_model, adc_bits=16, bandwidth_hz=50.0)
    run = simulate(model, "stationary", 1000.0, 8, initial_random=False)
    nz = identify_noise(run.accel[:, 0], model.rate_hz)
    s, rho = noise_sigma_rho(model)
    d_sampled = s * math.sqrt(2 * model.Ts * (1 + rho) / (1 - rho))
    assert nz.terms.density_one_sided == pytest.approx(d_sampled, rel=0.10)


def test_derivative_variance_and_refusal():
    y = np.array([0.0, 1.0, 3.0, 6.0])
    assert derivative_variance(y, 0.5) == pytest.approx(np.var([1.0, 2.0, 3.0]) / 0.25)
    with pytest.raises(ValueError, match="too few"):
        allan_deviation(np.ones(10), 100.0)
