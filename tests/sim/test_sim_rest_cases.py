"""Issue 31's simulated cases: each truth self-consistent (u = dr/dt, a = du/dt, true rests still), the
features each case is made for, fixes on the truth within their sigma, and the sim command lists them and
writes the fixes a user gives to smooth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from accelnav.estimate.fixes import read_fixes
from accelnav.estimate.zupt import intervals
from accelnav.hil_sim.sim.sensor import SimRun, simulate
from accelnav.hil_sim.sim.trajectories import FIX_PLANS, WALK_SCENARIOS, rest_truth, town_drive_end
from accelnav.hil_sim.sim.walking import scenario_walk
from accelnav.model.load import load_model
from accelnav.resources import models_dir

CASES = {  # scenario: (model, duration s)
    "highway_gnss": ("default", 200.0),
    "town_drive": ("default", 600.0),
    "hand_box": ("default", 90.0),
    "walking_still_start": ("foot", 30.0),
    "tilting_mount": ("default", 200.0),
    "jogging": ("foot", 30.0),
}


@pytest.fixture(scope="module")
def runs():
    models = {"default": load_model(None), "foot": load_model(models_dir() / "foot_imu.toml")}
    return {name: simulate(models[m], name, dur, 3).to_arrays() for name, (m, dur) in CASES.items()}


def fine_truth(scenario: str, seconds: float, rate: float):
    """(t, r, u, a) of a scenario's motion (first axis) on a fine grid, from the truth functions themselves."""
    t = np.arange(int(seconds * rate)) / rate
    ss = np.random.SeedSequence(3).spawn(1)[0]
    if scenario in WALK_SCENARIOS:
        w = scenario_walk(scenario, t, ss, 16 * 9.80665)
        return t, w.r[:, 0], w.u[:, 0], w.a[:, 0]
    v = rest_truth(scenario, t, ss, 50 * 9.80665, 1)
    return t, v.r, v.u, v.a


@pytest.mark.parametrize("scenario", CASES)
def test_truth_is_self_consistent(runs, scenario):
    """Velocity integrates to the position and acceleration to the velocity (trapezoids on a 5 kHz grid, where
    their own error is below 1e-4 of the span; a 1 % slip in either fails), and true rests have u = a = 0
    exactly."""
    t, r, u, a = fine_truth(scenario, 20.0 if scenario in WALK_SCENARIOS else 120.0, 5000.0)
    dr = cumulative_trapezoid(u, t, initial=0.0)
    du = cumulative_trapezoid(a, t, initial=0.0)
    assert np.abs(r - r[0] - dr).max() < 1e-4 * np.ptp(r), np.abs(r - r[0] - dr).max()
    assert np.abs(u - u[0] - du).max() < 1e-4 * np.ptp(u), np.abs(u - u[0] - du).max()
    d = runs[scenario]
    rest = d["rest"]
    assert np.all(d["u"][rest] == 0) and np.all(d["a"][rest] == 0)


@pytest.mark.parametrize("scenario", sorted(FIX_PLANS))
def test_fixes_lie_on_the_truth_within_their_sigma(runs, scenario):
    d = runs[scenario]
    period, sigma = FIX_PLANS[scenario]
    f = d["sim_fixes"]
    k = np.rint(f[:, 0] / float(d["t"][1])).astype(int)
    j = f[:, 1].astype(int)
    z = (f[:, 2] - d["r"][k, j]) / f[:, 3]
    assert np.all(f[:, 3] == sigma)
    assert 0.75 < np.sqrt(np.mean(z**2)) < 1.25 and np.abs(z).max() < 4.5, (np.sqrt(np.mean(z**2)), np.abs(z).max())
    for col in range(d["r"].shape[1]):
        times = f[j == col, 0]
        assert np.allclose(np.diff(times), period) and times[0] == 0.0 and times[-1] > d["t"][-1] - period


def test_highway_never_stops_and_cruise_reads_below_the_noise(runs):
    d = runs["highway_gnss"]
    u = d["u"][:, 0]
    assert not d["rest"].any() and 8.0 <= u.min() and u.max() <= 20.0
    cruise = d["a"][:, 0] == 0  # the holds at a constant speed
    assert 0.3 < cruise.mean() < 0.95
    m = load_model(None)
    seen = d["accel"][:, 0] - d["eps"][:, 0]  # what the sensor reads besides the bias: vibration + noise
    assert np.std(seen[cruise]) < 1.3 * np.sqrt(m.noise.R)


def test_town_drive_parks_at_both_ends_with_three_short_stops(runs):
    d = runs["town_drive"]
    t, rest, u = d["t"], d["rest"], d["u"][:, 0]
    stops = [(t[a], t[b - 1] - t[a]) for a, b in intervals(rest)]
    assert rest[0] and rest[-1] and len(stops) == 5, stops
    assert 10.0 <= stops[0][1] <= 20.01 and all(3.0 <= s <= 5.01 for _, s in stops[1:4])
    end = town_drive_end(np.random.SeedSequence(3).spawn(1)[0])
    assert abs(stops[-1][0] - end) < 0.02 and u.max() <= 16.0 and u.min() == 0.0
    assert np.abs(d["a"][:, 0]).max() <= 3.0 + 1e-9


def test_hand_box_moves_slowly_with_pauses(runs):
    d = runs["hand_box"]
    pauses = [(b - a) / 100.0 for a, b in intervals(d["rest"])]
    assert np.abs(d["u"][:, 0]).max() <= 0.6 and np.abs(d["u"][:, 0]).max() > 0.3
    assert len(pauses) >= 8 and min(pauses[1:-1]) >= 2.0 - 0.011


def test_still_start_stand_begins_two_tenths_in(runs):
    d = runs["walking_still_start"]
    first = intervals(d["rest"])[0]
    dt = float(d["t"][1])
    assert first[0] == round(0.2 / dt) and 2.0 <= (first[1] - first[0]) * dt <= 4.4
    moved = np.linalg.norm(d["r"][first[0]])  # the jostle moved the foot 2 cm before the stand
    assert abs(moved - 0.02) < 1e-9 and np.linalg.norm(d["u"][: first[0]], axis=1).max() > 0.1


def test_tilting_mount_level_drifts_within_the_band_also_when_stopped(runs):
    d = runs["tilting_mount"]
    plain = simulate(load_model(None), "stop_and_go", 200.0, 3).to_arrays()
    assert np.array_equal(d["u"], plain["u"])
    t = d["t"]
    truth = rest_truth("tilting_mount", t, np.random.SeedSequence(3).spawn(1)[0], 50 * 9.80665, 3)
    assert np.array_equal(truth.rest, d["rest"])
    rate = np.diff(truth.extra[::100], axis=0)  # m/s^2 per second, each axis
    assert np.abs(rate).max() <= 0.11 + 1e-9
    banded = (np.abs(rate) >= 0.015 - 1e-9).mean(axis=0)  # a second holding a knot may mix two rates
    assert np.all(banded > 0.85), banded
    stopped = d["rest"][::100][1:]
    assert stopped.sum() > 30 and np.all(np.median(np.abs(rate[stopped]), axis=0) > 0.015)


def test_jogging_leaks_three_m_s2(runs):
    d = runs["jogging"]
    plain = simulate(load_model(models_dir() / "foot_imu.toml"), "jogging", 30.0, 3).to_arrays()
    assert np.array_equal(d["accel"], plain["accel"])  # same seed, same run
    rest = d["rest"]
    size = np.linalg.norm(d["accel"][rest] - d["eps"][rest], axis=1)  # at rest the sensor reads the leak
    assert 2.3 < np.median(size) < 3.7
    lengths = np.array([b - a for a, b in intervals(rest)]) / 200.0
    assert len(lengths) >= 35 and lengths.max() <= 0.28


def test_round_trip_keeps_the_fixes(runs):
    d = runs["hand_box"]
    back = SimRun.from_arrays(load_model(None), d).to_arrays()
    assert np.array_equal(back["sim_fixes"], d["sim_fixes"]) and np.array_equal(back["rest"], d["rest"])


def test_sim_cli_lists_the_cases_and_writes_fixes_smooth_reads(tmp_path, capsys):
    from accelnav.cli import main

    assert main(["sim", "--list-scenarios"]) == 0
    assert set(CASES) <= set(capsys.readouterr().out.split())
    out, fx = tmp_path / "box.npz", tmp_path / "box_fixes.csv"
    assert main(["sim", "--scenario", "hand_box", "--duration", "30", "--seed", "2", "--out", str(out),
                 "--csv", str(tmp_path / "box.csv"), "--fixes-out", str(fx)]) == 0  # fmt: skip
    run = np.load(out)
    per_axis = read_fixes(fx, run["t"], [str(a) for a in run["axis_names"]])
    rows = run["sim_fixes"]
    for j, fixes in enumerate(per_axis):
        mine = rows[rows[:, 1] == j]
        assert [m.k for m in fixes] == list(np.rint(mine[:, 0] * 100).astype(int))
        assert [m.z for m in fixes] == list(mine[:, 2]) and len(fixes) == 6
    assert main(["smooth", str(out), "--fixes", str(fx), "--out", str(tmp_path / "s.npz")]) == 0


def test_sim_cli_refuses_fixes_of_a_case_without_them(tmp_path, capsys):
    from accelnav.cli import main

    code = main(["sim", "--scenario", "jogging", "--out", str(tmp_path / "j.npz"), "--fixes-out", str(tmp_path / "f")])
    err = capsys.readouterr().err.strip()
    assert code != 0 and len(err.splitlines()) == 1 and "has no position fixes" in err and "town_drive" in err
    assert not (tmp_path / "j.npz").exists()
