"""accelnav calibrate: pose detection, recovery of simulated offsets and sensitivities, interval coverage, refusals."""

from __future__ import annotations

import numpy as np
import pytest
from support.calibrate_cases import (
    POSE_S,
    any_recording,
    calibrate_any,
    nominal,
    perturbed,
    save_g_csv,
    truth_offset_scale,
    tumble_recording,
)

import accelnav
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.sim.trajectories import (
    TUMBLE_ANY_MIN_TURN_DEG,
    TUMBLE_HOLD_S,
    tumble_any_poses,
    tumble_poses,
    tumble_specific_force,
)
from accelnav.identify.calibrate import GRAVITY, CalibrationError, calibrate, detect_poses, fit_axes, native
from accelnav.identify.calibration import steps_and_noise
from accelnav.model.load import G0


def calibrate_arrays(nom, acc):
    steps, noise = steps_and_noise(nom)
    poses = detect_poses(acc, nom.rate_hz, steps=steps, noise_sd=noise)
    return fit_axes(poses, tuple(a.name for a in nom.axes))


def test_tumble_scenario_holds_the_six_positions():
    t = np.arange(0, 6 * POSE_S, 0.01)
    f = tumble_specific_force(t, 3, G0)
    assert np.allclose(np.linalg.norm(f, axis=1), G0)  # a rotation: gravity's length is kept
    held = t % POSE_S < TUMBLE_HOLD_S
    k = (t // POSE_S).astype(int)
    assert np.allclose(f[held], G0 * tumble_poses(3)[k[held]])
    f2 = tumble_specific_force(t, 2, G0)
    assert f2.shape == (len(t), 2) and np.allclose(f2, f[:, :2])  # a 2-axis part: the in-plane components


def test_detects_the_poses_of_a_two_axis_tumble():
    nom = nominal()
    run, acc = tumble_recording(nom, nom, 1)
    cal = calibrate_arrays(nom, acc)
    levels = [tuple(int(v) for v in p.level) for p in cal.poses]
    assert levels == [(1, 0), (-1, 0), (0, 1), (0, -1), (0, 0), (0, 0)]
    # every pose covers most of its hold and reaches at most 0.5 s into a turn (a turn about an in-plane axis
    # starts as 1 - cos: the first 0.4 s change the reading by less than the noise)
    for p in cal.poses:
        assert p.t1 - p.t0 > 0.9 * (TUMBLE_HOLD_S - 1.0)
        assert (p.t1 % POSE_S) <= TUMBLE_HOLD_S + 0.5
    # what a 2-axis part cannot identify is said
    assert all(any("out-of-plane" in m for m in a.not_identified) for a in cal.axes)


def test_recovers_offsets_and_scales_with_coverage_over_seeds():
    nom = nominal()
    z = []
    for seed in range(20):
        true = perturbed(nom, np.random.default_rng(100 + seed))
        _, acc = tumble_recording(nom, true, seed)
        cal = calibrate_arrays(nom, acc)
        for i, a in enumerate(cal.axes):
            o, s = truth_offset_scale(nom, true, i)
            lo, hi = a.ci95["offset"]
            z.append(("offset", lo <= o <= hi, (a.offset - o) / a.se["offset"]))
            lo, hi = a.ci95["scale"]
            z.append(("scale", lo <= s <= hi, (a.scale - s) / a.se["scale"]))
            # and the estimate itself is good: within 4 mg and 0.5 % (the perturbation is up to 130 mg and 3 %)
            assert abs(a.offset - o) < 4e-3 * G0 and abs(a.scale - s) < 5e-3
    covered = np.mean([c for _, c, _ in z])
    # 80 nominal 95 % intervals: the binomial 99 % band is about [0.89, 1.0]
    assert covered >= 0.87, covered
    # and not covering by being far too wide: |z| of a standard normal has median 0.67
    assert np.median(np.abs([v for *_, v in z])) > 0.35


def test_three_axis_six_position_with_cross_terms():
    nom = nominal(3)
    true = perturbed(nom, np.random.default_rng(7))
    _, acc = tumble_recording(nom, true, 7)
    cal = calibrate_arrays(nom, acc)
    assert len(cal.poses) == 6
    for i, a in enumerate(cal.axes):
        o, s = truth_offset_scale(nom, true, i)
        assert abs(a.offset - o) < 4 * a.se["offset"] + 1e-9
        assert abs(a.scale - s) < 4 * a.se["scale"]
        # the simulated part has no cross-axis sensitivity: each cross term is ~0 within its interval
        assert set(a.cross) == {n.name for n in nom.axes} - {a.name}
        for k, v in a.cross.items():
            assert abs(v) < 4 * a.se[k] + 1e-4
        assert not a.not_identified


def test_native_units_round_trip():
    nom = nominal()
    true = perturbed(nom, np.random.default_rng(3))
    for i in range(2):
        o, s = truth_offset_scale(nom, true, i)
        z, sens = native(nom.axes[i], o, s)
        assert z == pytest.approx(true.axes[i].zero_g, rel=1e-12) and sens == pytest.approx(true.axes[i].sensitivity)


def test_calibration_error_is_a_value_error():
    with pytest.raises(CalibrationError, match="too few"):
        detect_poses(np.zeros((10, 2)), 100.0)


# --------------------------------------------------------------------------
# poses in any orientation (3 axes): the gravity-magnitude fit


def test_tumble_any_scenario_holds_random_still_poses():
    rng = np.random.default_rng(5)
    poses = tumble_any_poses(rng, 30)
    assert np.allclose(np.linalg.norm(poses, axis=1), 1.0)
    turns = np.degrees(np.arccos(np.clip(np.sum(poses[1:] * poses[:-1], axis=1), -1, 1)))
    assert turns.min() >= TUMBLE_ANY_MIN_TURN_DEG
    assert np.allclose(tumble_any_poses(np.random.default_rng(5), 10), poses[:10])  # a prefix
    # spread over the sphere: every component takes both signs
    assert np.all(poses.max(axis=0) > 0.5) and np.all(poses.min(axis=0) < -0.5)
    t = np.arange(0, 10 * POSE_S, 0.01)
    f = tumble_specific_force(t, 3, G0, poses)
    assert np.allclose(np.linalg.norm(f, axis=1), G0)  # turns are rotations
    held = t % POSE_S < TUMBLE_HOLD_S
    k = (t // POSE_S).astype(int)
    assert np.allclose(f[held], G0 * poses[k[held]])
    # the simulator's scenario: the truth is those poses' gravity, r = u = 0
    nom = nominal(3)
    run = simulate(nom, "tumble_any", 3 * POSE_S, 4)
    assert np.allclose(np.linalg.norm(run.a, axis=1), G0) and not run.u.any() and not run.r.any()


def test_recovers_offsets_and_scales_from_random_poses_with_coverage_over_seeds():
    nom = nominal(3)
    z = []
    for seed in range(20):
        true = perturbed(nom, np.random.default_rng(300 + seed))
        _, acc = any_recording(nom, true, 200 + seed, n_poses=16)
        cal = calibrate_any(nom, acc)
        assert cal.method == GRAVITY and len(cal.poses) == 16
        for i, a in enumerate(cal.axes):
            o, s = truth_offset_scale(nom, true, i)
            for lab, est, tr in (("offset", a.offset, o), ("scale", a.scale, s)):
                lo, hi = a.ci95[lab]
                z.append((lo <= tr <= hi, (est - tr) / a.se[lab]))
            # the estimate itself: within 4 se, 10 mg and 1 % (the perturbation is up to 130 mg and 3 %)
            assert abs(a.offset - o) < min(4 * a.se["offset"], 10e-3 * G0)
            assert abs(a.scale - s) < min(4 * a.se["scale"], 0.01)
        # the simulated axes are square: each angle term is ~0 within its interval
        assert [p.name for p in cal.pairs] == ["x-y", "x-z", "y-z"]
        for p in cal.pairs:
            assert abs(p.value) < 4 * p.se, p
    covered = np.mean([c for c, _ in z])
    # 120 nominal 95 % intervals: the binomial 99 % band is about [0.90, 0.99]
    assert covered >= 0.90, covered
    assert np.median(np.abs([v for _, v in z])) > 0.35  # not covering by being far too wide


def test_random_poses_recover_an_angle_between_axes():
    """y made to see 1 % of x (its axis turned 10 mrad towards x): the x-y angle term finds it."""
    nom = nominal(3)
    _, acc = any_recording(nom, nom, 9, n_poses=16)
    mix = np.eye(3)
    mix[1, 0] = 0.01
    cal = calibrate_any(nom, acc @ mix.T)
    pairs = {p.name: p for p in cal.pairs}
    assert abs(pairs["x-y"].value - 0.01) < 4 * pairs["x-y"].se and pairs["x-y"].se < 0.003
    assert abs(pairs["x-z"].value) < 4 * pairs["x-z"].se and abs(pairs["y-z"].value) < 4 * pairs["y-z"].se


def test_fewer_than_ten_random_poses_fit_offsets_and_scales_only():
    nom = nominal(3)
    true = perturbed(nom, np.random.default_rng(8))
    _, acc = any_recording(nom, true, 8, n_poses=7)
    cal = calibrate_any(nom, acc)
    assert cal.method == GRAVITY and len(cal.poses) == 7 and not cal.pairs
    assert any("angles between the axes" in m and "found 7" in m for m in cal.axes[0].not_identified)
    for i, a in enumerate(cal.axes):
        o, s = truth_offset_scale(nom, true, i)
        assert abs(a.offset - o) < 4 * a.se["offset"] and abs(a.scale - s) < 4 * a.se["scale"]


def _synthetic(ups, seed=0, noise_g=1e-3):
    """Still poses with the given up vectors, exact part, white noise: (acc, rate)."""
    t = np.arange(0, len(ups) * POSE_S, 0.01)
    f = tumble_specific_force(t, 3, G0, np.asarray(ups, dtype=float))
    return f + noise_g * G0 * np.random.default_rng(seed).standard_normal(f.shape), 100.0


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize(
    "ups, message",
    [
        # five tilted poses: 6 unknowns
        (_unit([[1, 1, 0], [0, 1, 1], [1, 0, 1], [-1, 1, 1], [1, -1, -1]]), "found 5 still pose(s), some tilted"),
        # turned about z only: every up vector in the x-y plane
        (
            [[np.cos(a), np.sin(a), 0.0] for a in np.radians([10, 70, 130, 190, 250, 310, 40, 100])],
            "lie near one plane (rms 0 deg out of it; its normal: x +0.00, y +0.00, z +1.00)",
        ),
        # a tilted plane (normal (1, 1, 1))
        (
            [np.cos(a) * _unit([1, -1, 0]) + np.sin(a) * _unit([1, 1, -2]) for a in np.radians(np.arange(0, 360, 45))],
            "lie near one plane (rms 0 deg out of it; its normal: x +0.58, y +0.58, z +0.58)",
        ),
        # within 9 degrees of one tilted direction (1, 1, 1), up or down
        (
            [
                _unit(
                    (-1) ** k * _unit([1, 1, 1])
                    + 0.15 * (np.cos(a) * _unit([1, -1, 0]) + np.sin(a) * _unit([1, 1, -2]))
                )
                for k, a in enumerate(np.radians(np.arange(0, 360, 45)))
            ],
            "lie within about 9 deg of one direction (up = x +0.58, y +0.58, z +0.58 and its opposite)",
        ),
        # within 17 degrees of z up or down: x (and y) never read far from 0 g
        (
            [
                _unit([np.cos(a) * 0.3, np.sin(a) * 0.3, (-1) ** k])
                for k, a in enumerate(np.radians(np.arange(0, 360, 45)))
            ],
            "axis x: every pose reads it between -0.29 and +0.29 g (near the plane of the other axes)",
        ),
        # z always between +0.41 and +0.55 g: its offset and sensitivity trade against each other
        (
            [
                _unit([np.cos(a), np.sin(a), 0.45 + 0.1 * (k % 3)])
                for k, a in enumerate(np.radians(np.arange(0, 360, 40)))
            ],
            "axis z: every pose reads it between +0.41 and +0.55 g (all poses near one direction of it)",
        ),
    ],
)
def test_degenerate_random_pose_sets_are_refused(ups, message):
    acc, rate = _synthetic(ups)
    poses = detect_poses(acc, rate)
    assert len(poses) == len(ups)
    with pytest.raises(CalibrationError) as exc:
        calibrate(poses, ("x", "y", "z"))
    assert message in str(exc.value), str(exc.value)
    assert "\n" not in str(exc.value)


def test_calibrate_recording_of_a_tumble(tmp_path):
    """accelnav.calibrate (what ``accelnav calibrate tumble.csv --model nominal.toml`` writes) on the six poses."""
    nom = nominal()
    true = perturbed(nom, np.random.default_rng(11))
    run, acc = tumble_recording(nom, true, 11)
    r = accelnav.calibrate(save_g_csv(tmp_path / "tumble.csv", run.t, acc), nom)
    assert len(r.calibration.poses) == 6 and any(a.not_identified for a in r.calibration.axes)
    for i, a in enumerate(r.model.axes):
        t = true.axes[i]
        # 4.5 standard errors of the offset in volts (se ~ 1 mg = 0.04 mV) and of the sensitivity
        assert a.zero_g == pytest.approx(t.zero_g, abs=3e-4)
        assert a.sensitivity == pytest.approx(t.sensitivity, rel=5e-3)
        assert a.c2 == -a.c1


def test_calibrate_recording_of_random_poses(tmp_path):
    """accelnav.calibrate on twelve random still poses of a 3-axis part: the gravity-magnitude method."""
    nom = nominal(3)
    true = perturbed(nom, np.random.default_rng(12))
    run, acc = any_recording(nom, true, 12)
    r = accelnav.calibrate(save_g_csv(tmp_path / "any.csv", run.t, acc), nom)
    cal = r.calibration
    assert len(cal.poses) == 12 and cal.method == GRAVITY and "x-y" in [pc.name for pc in cal.pairs]
    for i, a in enumerate(r.model.axes):
        t = true.axes[i]
        assert a.zero_g == pytest.approx(t.zero_g, abs=4e-4)  # 10 mg in volts
        assert a.sensitivity == pytest.approx(t.sensitivity, rel=0.01)
