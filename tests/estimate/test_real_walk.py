"""The ZUPT detector on a REAL foot-mounted IMU walk, through the library as a notebook user would call it
(``accelnav.read_input`` of walk.csv, ``detect_rests``, ``smooth_run``: what ``accelnav smooth`` runs).

Data: gaitmap 2.6.0's example data (MaD-Lab Erlangen, MIT licence), fetched from
PyPI with pip, sha256-checked, never copied into this project; what it is, how
it is turned into two level-frame horizontal axes with gravity removed (the
input of issue #11's user), the truth (motion-capture heel marker at consecutive
midstances) and the reference stances (gyroscope-quiet, within the motion
capture's heel strike and toe-off): tests/support/realdata.py. Skipped, with the
reason, when PyPI cannot be reached.

Per foot (28 left, 29 right strides of 2 x 20 m with a turn), four estimates of
the stride length: the smoother with the detector's shipped defaults, with the
reference stances given as a per-sample mask file, without ZUPT, and plain
double integration. The behaviour asserted: with the defaults, mean
|stride-length error| <= 1.5 x what the reference stances give. The targets in
% of the stride length (issue #11's 5 %, issue #23's 3 % of distance) are
targets, not behaviour: bench/studies/study_real_rests.py prints them (goal, measured,
met) beside the reference stances' own figure.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import realdata

import accelnav
from accelnav.estimate.pipeline import dead_reckoning
from accelnav.estimate.zupt import ZuptParams, intervals
from accelnav.resources import models_dir

METHODS = ("defaults", "reference stances", "no ZUPT", "double integration")


def _model_text() -> str:
    """models/foot_imu.toml at the recording's 204.8 Hz (a calibrated sensor in m/s^2, +-16 g)."""
    text = (models_dir() / "foot_imu.toml").read_text()
    assert text.count("rate_hz = 200.0") == 1
    return text.replace("rate_hz = 200.0", f"rate_hz = {realdata.RATE}")


def _smooth(run, model, rest=None, params=None) -> dict:
    """What ``accelnav smooth --zupt auto|FILE`` computes, through the library: rests detected with ``params``
    when ``rest`` is "auto", read from a mask file when a path."""
    if isinstance(rest, str):
        rest = accelnav.detect_rests(run, model, params)
    return accelnav.smooth_run(run, model, rest=rest, zupt_params=params)


def _lengths(r: np.ndarray, mid: np.ndarray) -> np.ndarray:
    """Horizontal distance between the positions at consecutive midstances; r is (n_axes, N)."""
    return np.linalg.norm(np.diff(np.asarray(r).T[mid], axis=0), axis=1)


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    """Per foot: the stride-length errors of each method [m], the true lengths, the masks."""
    feet = realdata.load_walk()
    tmp = tmp_path_factory.mktemp("real_walk")
    model = tmp / "foot_imu_204_8.toml"
    model.write_text(_model_text())
    res = {}
    for foot in feet:
        csv = tmp / f"{foot.name}.csv"
        table = np.column_stack([foot.t, foot.horizontal])
        np.savetxt(csv, table, delimiter=",", header="t,ax,ay", comments="", fmt="%.7g")
        mask = tmp / f"{foot.name}_stances.csv"
        np.savetxt(mask, foot.reference.astype(int), header="rest", comments="", fmt="%d")
        run, m = accelnav.read_input(csv, model, axes=["ax", "ay"], time_column="t")
        auto = _smooth(run, m, "auto")
        ref = _smooth(run, m, mask)
        plain = _smooth(run, m)
        old = _smooth(run, m, "auto", ZuptParams(tremor=0.0))
        estimates = {
            "defaults": auto["smooth_x"][:, :, 0],
            "reference stances": ref["smooth_x"][:, :, 0],
            "no ZUPT": plain["smooth_x"][:, :, 0],
            "double integration": dead_reckoning(plain, m)[:, :, 0],
            "tremor 0 (before)": old["smooth_x"][:, :, 0],
        }
        err = {k: _lengths(r, foot.midstance) - foot.true_length for k, r in estimates.items()}
        res[foot.name] = {"foot": foot, "err": err, "rest": auto["zupt"][:, 0]}
    lines = [f"{'foot':<7}{'method':<22}{'strides':>8}{'mean |e| [cm]':>15}{'[%]':>7}{'max [cm]':>10}"]
    for name, r in res.items():
        mean_len = r["foot"].true_length.mean()
        for k, e in r["err"].items():
            cm = 100 * np.abs(e)
            lines.append(f"{name:<7}{k:<22}{len(e):>8}{cm.mean():15.1f}{cm.mean() / mean_len:7.1f}{cm.max():10.1f}")
    print("\nReal walk (gaitmap example, 204.8 Hz), stride length against the motion capture:\n" + "\n".join(lines))
    return res


def _mean_abs(r, method) -> float:
    return float(np.mean(np.abs(r["err"][method])))


@pytest.mark.parametrize("foot", ["left", "right"])
def test_defaults_as_good_as_the_reference_stances(walk, foot):
    """Shipped defaults within 1.5 x the reference stances (the detector's part of issue #11's target)."""
    r = walk[foot]
    assert len(r["err"]["defaults"]) >= 25
    auto, ref = _mean_abs(r, "defaults"), _mean_abs(r, "reference stances")
    assert auto <= 1.5 * ref, f"{foot}: defaults {100 * auto:.1f} cm, reference stances {100 * ref:.1f} cm"
    # the walk needs the updates: without them, or integrating twice, the strides are far off
    for method in ("no ZUPT", "double integration"):
        assert _mean_abs(r, method) > 3 * auto, (method, _mean_abs(r, method), auto)


@pytest.mark.parametrize("foot", ["left", "right"])
def test_every_stance_is_found_and_no_swing(walk, foot):
    """One decision per sample: each reference stance holds updates, and no update lands far from a stance."""
    r = walk[foot]
    rest, ref = r["rest"], r["foot"].reference
    found = [rest[a:b].mean() for a, b in intervals(ref)]
    assert np.mean(np.array(found) > 0.3) >= 0.95, np.round(found, 2)
    # a swing: more than 0.1 s from any reference stance and not the standing before the first or after the last
    mid = r["foot"].midstance
    near = np.zeros_like(ref)
    pad = int(0.1 * realdata.RATE)
    for a, b in intervals(ref):
        near[max(0, a - pad) : b + pad] = True
    swing = ~near
    swing[: mid[0]] = swing[mid[-1] :] = False
    assert rest[swing].mean() < 0.05, rest[swing].mean()


def test_the_quiet_test_without_the_tremor_term_fails_on_this_walk(walk):
    """The test can fail: the detector as merged (variance bound from the sensor noise alone) misses stances."""
    worse = [_mean_abs(r, "tremor 0 (before)") > 1.5 * _mean_abs(r, "reference stances") for r in walk.values()]
    assert any(worse)


def test_truth_agrees_with_the_data_sets_own_per_stride_positions(walk):
    """Our stride truth (heel marker at the midstances, mapped 204.8 -> 100 Hz) is position_sample.csv's end point.

    position_sample.csv is the same motion capture cut per stride by the data set's authors: this checks the
    clock mapping and the marker choice, not the estimator.
    """
    for r in walk.values():
        foot = r["foot"]
        assert np.max(np.abs(foot.true_length - foot.gaitmap_length)) < 0.01
        assert 1.2 < np.median(foot.true_length) < 1.5
