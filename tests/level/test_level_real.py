"""accelnav.level on a REAL foot walk from its raw body-frame data (issue 35's acceptance on foot walks).

Data: gaitmap 2.6.0's example walk (tests/support/realdata.py: both feet, 204.8 Hz, acc in m/s^2 with gravity
and gyro, the motion capture's mid-stances and stride lengths, the reference stances). Per foot, the raw
accelerometer and gyroscope go through ``level_frame`` with its defaults; the baseline is the tests' own
hand-made levelling (realdata.level_frame: a strapdown re-levelled at the quietest point of each stance,
placed with the motion capture's help), from the same run.

Asserted, per foot:

* the residual level leak at mid-stance (the mean horizontal level-frame acceleration over +-0.05 s about
  each motion-capture mid-stance, rms over the stances) is at most 0.3 m/s^2;
* the stride error with the defaults (the rests ``level_frame`` found, handed to the smoother, and the same
  rests as the smoother's rest-decision candidates) is at most 1.2 x the stride error with the reference
  stances, all on ``level_frame``'s axes.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import realdata, realdata_more

import accelnav
from accelnav.level import ImuRecord, level_frame

LEAK_MAX = 0.3  # m/s^2, at mid-stance (issue 35)
STRIDE_RATIO = 1.2  # defaults against the reference stances (issue 35)
MID_HALF_S = 0.05  # s, the mid-stance window's half width


def mid_stance_leak(horizontal: np.ndarray, midstance: np.ndarray) -> float:
    """rms over the mid-stances of the mean horizontal acceleration over +-MID_HALF_S about each."""
    k = int(round(MID_HALF_S * realdata.RATE))
    m = np.array([horizontal[i - k : i + k + 1].mean(axis=0) for i in midstance])
    return float(np.sqrt(np.mean(np.sum(m * m, axis=1))))


def stride_error(horizontal: np.ndarray, foot, rest, tmp, candidates=None) -> float:
    """Mean |stride-length error| [m] of the smoother on ``horizontal`` with the rests ``rest`` (a mask, or
    "auto": the rest decision on the accelerometer-only detector's candidates or on ``candidates``)."""
    model = tmp / "foot_204_8hz.toml"
    model.write_text(realdata_more.model_text(realdata.RATE, ("x", "y"), 10.0, 5000.0))
    csv = tmp / f"{foot.name}_level.csv"
    np.savetxt(csv, np.column_stack([foot.t, horizontal]), delimiter=",", header="t,ax,ay", comments="", fmt="%.7g")
    run, m = accelnav.read_input(csv, model, axes=["ax", "ay"], time_column="t")
    if isinstance(rest, str):
        rest = accelnav.detect_rests(run, m, candidates=candidates)
    r = np.asarray(accelnav.smooth_run(run, m, rest=rest)["smooth_x"])[:, :, 0].T[foot.midstance]
    return float(np.mean(np.abs(np.linalg.norm(np.diff(r, axis=0), axis=1) - foot.true_length)))


@pytest.fixture(scope="module")
def feet(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("level_real")
    out = {}
    lines = [f"{'foot':<6}{'levelling':<22}{'leak mid-stance':>16}{'defaults [cm]':>14}{'true rests [cm]':>16}"]
    for foot in realdata.load_walk():
        acc, gyro = realdata.body_frame(foot.name)
        lev = level_frame(ImuRecord(foot.t, acc, gyro=gyro, source=f"gaitmap {foot.name}"))
        h = lev.acc[:, :2]
        res = {
            "level": lev,
            "leak": mid_stance_leak(h, foot.midstance),
            "defaults": stride_error(h, foot, lev.rests, tmp),
            "true": stride_error(h, foot, foot.reference, tmp),
            "auto": stride_error(h, foot, "auto", tmp),
            "decided": stride_error(h, foot, "auto", tmp, candidates=lev.rests),
            "base leak": mid_stance_leak(foot.horizontal, foot.midstance),
            "base true": stride_error(foot.horizontal, foot, foot.reference, tmp),
            "base auto": stride_error(foot.horizontal, foot, "auto", tmp),
        }
        out[foot.name] = res
        for k, (leak, d, t) in {
            "accelnav.level": (res["leak"], res["defaults"], res["true"]),
            "  (smoother's auto)": (res["leak"], res["auto"], res["true"]),
            "  (decided on them)": (res["leak"], res["decided"], res["true"]),
            "hand-made (baseline)": (res["base leak"], res["base auto"], res["base true"]),
        }.items():
            lines.append(f"{foot.name:<6}{k:<22}{leak:16.3f}{100 * d:14.2f}{100 * t:16.2f}")
        lines.append(f"{foot.name:<6}{lev.summary()}")
    print("\nLevelled from the raw body frame (gaitmap walk):\n" + "\n".join(lines))
    return out


@pytest.mark.parametrize("foot", ["left", "right"])
def test_level_leak_at_mid_stance(feet, foot):
    r = feet[foot]
    assert r["leak"] <= LEAK_MAX, f"{foot}: {r['leak']:.3f} m/s^2 at mid-stance (baseline {r['base leak']:.3f})"
    # the figure the result states is of the same kind: it names the rests it is measured over
    assert np.isfinite(r["level"].leak) and r["level"].leak <= LEAK_MAX
    assert "rests found by the gyroscope" in " ".join(r["level"].notes)


@pytest.mark.parametrize("foot", ["left", "right"])
def test_stride_error_with_defaults_near_the_true_rests(feet, foot):
    r = feet[foot]
    assert r["defaults"] <= STRIDE_RATIO * r["true"], (foot, r["defaults"], r["true"])
    # the same rests handed to the smoother's rest decision as its candidates (detect_rests(candidates=))
    assert r["decided"] <= STRIDE_RATIO * r["true"], (foot, r["decided"], r["true"])


def test_without_the_rest_correction_the_leak_fails(feet):
    """The test can fail: Fusion's attitude alone (passes=0) leaks more than the bound at mid-stance."""
    foot = realdata.load_walk()[0]
    acc, gyro = realdata.body_frame(foot.name)
    alone = level_frame(ImuRecord(foot.t, acc, gyro=gyro), passes=0)
    assert mid_stance_leak(alone.acc[:, :2], foot.midstance) > LEAK_MAX
