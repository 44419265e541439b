"""A fitted value printed beside a truth outside its 95 % interval says why, from the fit's own evidence."""

from __future__ import annotations

import numpy as np

from accelnav.identify.biasfit import fit_bias

T_TRUE, C1, C2, SIGMA = 300.0, 0.08, 0.05, 0.02


def _fit(seed: int, walk: float = 0.0):
    rng = np.random.default_rng(seed)
    t = np.arange(120_000) / 100.0
    y = C1 * -np.expm1(-t / T_TRUE) + C2 + SIGMA * rng.standard_normal(len(t))
    return fit_bias(t, y + walk * np.cumsum(rng.standard_normal(len(t))) * 0.1)


def test_a_truth_inside_its_interval_needs_no_word():
    f = _fit(1)
    lo, hi = f.interval("c2")
    assert lo <= C2 <= hi and f.why_truth_outside("c2", C2, white=True) == ""


def test_white_residuals_and_a_miss_is_the_one_in_twenty():
    f = _fit(1)
    assert "1 fit of 20" in f.why_truth_outside("c2", f.c2 + 10 * f.stderr("c2"), white=True)


def test_a_truth_the_widened_interval_holds_names_the_correlation():
    f = _fit(2, walk=1e-3)
    plain, widened = f.interval("c2")[1], f.ci95_lr[1][1]
    assert widened > plain  # correlated residuals widen it
    assert "residuals are correlated" in f.why_truth_outside("c2", 0.5 * (plain + widened), white=False)


def test_a_wandering_bias_is_named_when_even_the_widened_interval_misses():
    f = _fit(2, walk=1e-3)
    far = f.ci95_lr[1][1] + 1.0
    why = f.why_truth_outside("c2", far, white=False)
    assert "not white" in why and "random walk sigma_eps" in why and "[" in why


def test_a_fallback_to_a_constant_bias_is_named():
    rng = np.random.default_rng(3)
    t = np.arange(20_000) / 100.0
    f = fit_bias(t, 0.05 + 0.02 * rng.standard_normal(len(t)))  # no warm-up in it: T cannot be identified
    assert not f.T_identified
    assert "constant bias" in f.why_truth_outside("c2", 1.0, white=True)
