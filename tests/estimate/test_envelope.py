"""A run's series decimated while they stream (accelnav.estimate.envelope): each bin's min and max are those of
its samples, whatever cut of the run fed them, and a short run keeps every sample."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.estimate.envelope import Envelope


@pytest.fixture(scope="module")
def series():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.standard_normal((10_007, 3)), axis=0)
    x[5000, 1] = 1e6  # one spike: a plot of the envelope must show it
    return x


@pytest.mark.parametrize("chunk", [1, 7, 1000, 3333, 10_007])
def test_each_bin_holds_the_min_and_max_of_its_samples_whatever_the_chunks(series, chunk):
    n = len(series)
    env = Envelope(n, bins=100)
    for s in range(0, n, chunk):
        env.add("x", s, series[s : s + chunk])
    edges = env.edges
    assert edges[0] == 0 and edges[-1] == n and np.all(np.diff(edges) >= n // 100)
    want_lo = np.array([series[a:b].min(axis=0) for a, b in zip(edges[:-1], edges[1:], strict=True)])
    want_hi = np.array([series[a:b].max(axis=0) for a, b in zip(edges[:-1], edges[1:], strict=True)])
    np.testing.assert_array_equal(env.lo["x"], want_lo)
    np.testing.assert_array_equal(env.hi["x"], want_hi)
    lines = env.lines("x")
    assert lines.shape == (200, 3) and np.nanmax(lines[:, 1]) == 1e6
    np.testing.assert_array_equal(lines[0::2], want_lo)


def test_a_short_run_keeps_every_sample_and_bools_say_any():
    env = Envelope(5, bins=100)
    env.add("t", 0, np.arange(5.0))
    env.add("m", 0, np.array([[False, True], [False, False]]))
    env.add("m", 2, np.array([[False, False], [True, False], [False, False]]))
    assert env.bins == 5
    np.testing.assert_array_equal(env.times(), np.repeat(np.arange(5.0), 2))
    np.testing.assert_array_equal(env.hi["m"][:, 0] > 0, [False, False, False, True, False])
    np.testing.assert_array_equal(env.hi["m"][:, 1] > 0, [True, False, False, False, False])


def test_samples_outside_the_run_are_refused():
    env = Envelope(10, bins=4)
    with pytest.raises(ValueError, match="outside 0..9"):
        env.add("x", 8, np.zeros(3))
