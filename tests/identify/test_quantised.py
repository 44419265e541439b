"""The read-out step's model: its grid found in converted samples, the noise it hides, the bound on the mean."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from accelnav.identify.quantised import HIDDEN_BELOW, advice, grid_step, quantisation

Q = 0.1451  # m/s^2: 5 V / 1024 / 0.33 V/g x g0, the Uno's step for an ADXL335 at 3.3 V


def _read(mu, sigma, n, seed):
    x = mu + sigma * np.random.default_rng(seed).standard_normal(n)
    return Q * np.round(x / Q)


def test_grid_step_of_converted_codes_and_of_none():
    codes = np.array([336, 337, 339, 338, 340, 337])
    y = codes * (5 / 1024 / 0.33 * 9.80665) - 1.65 / 0.33 * 9.80665  # as the model's conversion makes them
    assert grid_step(y) == pytest.approx(5 / 1024 / 0.33 * 9.80665, rel=1e-9)
    written = np.round(y / 9.80665, 6) * 9.80665  # converted to g and written with 6 decimals
    assert grid_step(written) == pytest.approx(5 / 1024 / 0.33 * 9.80665, rel=1e-4)
    assert grid_step(np.random.default_rng(1).standard_normal(1000)) == 0.0  # continuous samples: no grid
    assert grid_step(np.full(10, 0.3)) == 0.0  # one value: no spacing to read


@pytest.mark.parametrize("offset", [0.0, 0.25, 0.5])
@pytest.mark.parametrize("sigma_steps", [0.05, 0.1, 0.18, 0.3, 0.7])
def test_the_codes_shares_bound_the_noise_where_the_spread_cannot(sigma_steps, offset):
    """Half a step off a code, any noise well under a step gives two codes half and half: the spread says 0.41
    step whatever the noise; the shares of the codes bound it (and give it where a third code shows)."""
    y = _read((12 + offset) * Q, sigma_steps * Q, 100_000, 3)
    q = quantisation(y, y - y.mean(), Q, "test")
    lo, hi = q.noise_ci
    assert lo <= sigma_steps * Q <= hi, (q.noise_sd / Q, lo / Q, hi / Q)
    if sigma_steps >= 0.3:
        assert not q.hidden and hi - lo < 0.2 * sigma_steps * Q  # seen, and closely
    if sigma_steps <= 0.1:
        assert q.hidden


def test_a_still_signal_on_two_codes_tells_no_noise():
    y = _read(12.5 * Q, 0.05 * Q, 20_000, 4)  # exactly between two codes, no third: any small noise fits
    q = quantisation(y, y - y.mean(), Q, "test")
    assert q.hidden and q.noise_ci[0] <= 0.02 * Q * 1.001  # the interval runs down to the grid's end
    assert q.bias_bound == pytest.approx(Q / 2, rel=0.05) and q.noise_ci[1] < 0.3 * Q  # no third code: small


@pytest.mark.parametrize("sigma_steps", [0.1, 0.18, 0.3, 0.6])
@pytest.mark.parametrize("offset", [0.0, 0.2, 0.37])
def test_the_mean_of_the_readings_lies_within_the_bound(sigma_steps, offset):
    mu = (12 + offset) * Q
    y = _read(mu, sigma_steps * Q, 100_000, 7)
    q = quantisation(y, y - y.mean(), Q, "test")
    sampling = 4 * y.std() / np.sqrt(len(y)) + 1e-12
    assert abs(y.mean() - mu) <= q.bias_bound + sampling
    assert q.bias_bound <= Q / 2


def test_the_bound_is_needed_where_the_noise_is_hidden():
    """At a quarter step off a code with 0.1 step of noise the readings' mean is off by about a quarter step:
    far outside any interval from the spread alone, inside the bound."""
    mu = 12.25 * Q
    y = _read(mu, 0.1 * Q, 100_000, 5)
    q = quantisation(y, y - y.mean(), Q, "test")
    err = abs(y.mean() - mu)
    assert err > 50 * y.std() / np.sqrt(len(y)) and err <= q.bias_bound


def test_advice_is_one_line_with_the_fixes():
    y = _read(0.3 * Q, 0.1 * Q, 10_000, 2)
    q = quantisation(y, y - y.mean(), Q, "the model's read-out")
    q = dataclasses.replace(q, sensor_noise=0.013, finer="a 3.3 V reference (step 9.77 mg)")
    line = advice(q)
    assert "\n" not in line and "hides the noise" in line and f"under {HIDDEN_BELOW:g} step" in line
    assert "dither" in line and "a 3.3 V reference" in line and "more ADC bits" in line
