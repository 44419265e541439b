"""Stride lengths of a simulated walk, smoothed with automatic rests through the library (the figure
``accelnav smooth --zupt auto`` prints; tests/sim/test_sim.py checks that it prints it)."""

from __future__ import annotations

import accelnav
from accelnav.estimate.pipeline import stride_table


def test_smoothed_strides_within_5_percent_on_a_simulated_walk():
    model = accelnav.load_model(None)
    run = accelnav.simulate(model, "walking", 20.0, seed=2)
    smoothed = accelnav.smooth_run(run, model, rest=accelnav.detect_rests(run, model))
    rows = {row.method: row for row in stride_table(dict(smoothed), model)}
    assert rows["smoother"].percent < 5.0, rows["smoother"]  # mean |error| in % of the stride
