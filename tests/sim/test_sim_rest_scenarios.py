"""The rest-detection scenarios of the simulator (issue 23): truth rests, consistent truth, prefix runs."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.sim.trajectories import REST_SCENARIOS, WALK_SCENARIOS

MOVING = ("stop_and_go_graded", "highway", "cart_push")


@pytest.mark.parametrize("scenario", REST_SCENARIOS)
def test_truth_rests_are_still_and_runs_are_prefixes(default_model, scenario):
    long = simulate(default_model, scenario, 40.0, 5).to_arrays()
    short = simulate(default_model, scenario, 20.0, 5).to_arrays()
    n = len(short["t"])
    for key in ("accel", "r", "u", "rest"):
        assert np.array_equal(long[key][:n], short[key]), key
    rest = long["rest"]
    assert np.all(long["u"][rest] == 0) and np.all(long["a"][rest] == 0)
    if scenario.startswith("highway"):
        assert not rest.any() and np.abs(long["u"][:, 0]).min() >= 8.0 and np.abs(long["u"][:, 0]).max() <= 20.0
    else:  # a box moved by hand pauses more than it moves
        assert 0.1 < rest.mean() < (0.8 if scenario == "hand_box" else 0.6)
    if scenario in WALK_SCENARIOS:
        assert np.array_equal(long["stance"], rest)
    for j in range(long["r"].shape[1]) if "sim_fixes" in long else ():
        a, b = (f[f[:, 1] == j] for f in (long["sim_fixes"], short["sim_fixes"]))
        assert len(b) and np.array_equal(a[: len(b)], b)


@pytest.mark.parametrize("scenario", MOVING)
def test_truth_is_consistent(default_model, scenario):
    """u = dr/dt and a = du/dt (the motion; the grade and vibration are read by the sensor only)."""
    d = simulate(default_model, scenario, 30.0, 2).to_arrays()
    dt = float(d["t"][1])
    for j in range(d["r"].shape[1]):
        assert np.abs(np.gradient(d["u"][:, j], dt) - d["a"][:, j])[2:-2].max() < 0.01
        assert np.abs(np.gradient(d["r"][:, j], dt) - d["u"][:, j])[2:-2].max() < 0.001


def test_graded_stops_read_the_slope_and_share_stop_and_go_motion(default_model):
    graded = simulate(default_model, "stop_and_go_graded", 60.0, 4).to_arrays()
    flat = simulate(default_model, "stop_and_go", 60.0, 4).to_arrays()
    seen = graded["accel"][:, 0] - flat["accel"][:, 0]
    rest = graded["rest"]
    assert np.array_equal(graded["u"], flat["u"])
    # g sin(theta), |theta| <= 4 degrees, and not zero at the stops
    assert np.abs(seen).max() <= 9.80665 * np.sin(np.radians(4.0)) + 0.1
    assert np.abs(seen[rest]).mean() > 0.05


def test_walking_drift_leak_grows(default_model):
    drift = simulate(default_model, "walking_drift", 60.0, 1).to_arrays()
    plain = simulate(default_model, "walking", 60.0, 1).to_arrays()
    assert np.array_equal(drift["r"], plain["r"])
    leak = np.linalg.norm(drift["accel"] - plain["accel"], axis=1)
    stance = drift["stance"]
    first, last = stance & (drift["t"] < 10), stance & (drift["t"] > 50)
    assert leak[first].mean() < 0.4 < 0.7 < leak[last].mean()


def test_fast_walk_has_short_stances(default_model):
    from accelnav.estimate.zupt import intervals

    d = simulate(default_model, "walking_fast", 30.0, 1).to_arrays()
    lengths = np.array([b - a for a, b in intervals(d["stance"])]) * float(d["t"][1])
    assert len(lengths) >= 35 and lengths.max() <= 0.22


def test_scenarios_are_listed(capsys):
    from accelnav.cli import main

    assert main(["sim", "--list-scenarios"]) == 0
    listed = capsys.readouterr().out.split()
    assert set(REST_SCENARIOS) <= set(listed)
