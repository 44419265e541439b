"""filter and smooth take recordings (CSV, gzip CSV, NPZ, logs) through one checked reader (issue #11)."""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from conftest import MODELS
from support.cli import run_cli as _run

from accelnav.data.runfile import load_run
from accelnav.estimate.pipeline import stance_midpoints, stride_lengths
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.load import load_model

FOOT = MODELS / "foot_imu.toml"


def _csv_lines(t, accel, t_name="t") -> list[str]:
    lines = [f"{t_name},ax,ay"]
    lines += [f"{ti:.6f},{a:.6f},{b:.6f}" for ti, (a, b) in zip(t, accel, strict=True)]
    return lines


@pytest.fixture(scope="module")
def walk():
    run = simulate(load_model(FOOT), "walking", 30.0, 5)
    return run


@pytest.fixture()
def rec(tmp_path, walk):
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(_csv_lines(walk.t, walk.accel)) + "\n")
    return path


def test_smooth_a_csv_on_a_calibrated_model_with_auto_zupt(rec, tmp_path, capsys, walk):
    argv = [
        "smooth",
        rec,
        "--model",
        FOOT,
        "--time-column",
        "t",
        "--axis",
        "ax",
        "--axis",
        "ay",
        "--zupt",
        "auto",
        "--full",
    ]
    status, out, err = _run([*argv, "--out", tmp_path / "o.npz"], capsys)
    assert status == 0, err
    assert "columns ax, ay -> model axes x, y" in out and "zero-velocity detector:" in out and " accepted" in out
    arrays, model = load_run(tmp_path / "o.npz")
    assert model.name == "foot_imu" and arrays["smooth_x"].shape == (2, len(walk.t), 4)
    # the strides come out right (the CSV has no truth; score against the simulation's)
    mids = stance_midpoints(walk.stance)
    est = stride_lengths(arrays["smooth_x"][:, :, 0].T, mids)
    true = stride_lengths(walk.r, mids)
    assert np.mean(np.abs(est - true)) < 0.05 * np.mean(true)


def test_gzip_csv_and_npz_recordings_are_read_too(tmp_path, capsys, walk):
    gz = tmp_path / "rec.csv.gz"
    gz.write_bytes(gzip.compress(("\n".join(_csv_lines(walk.t, walk.accel)) + "\n").encode()))
    npz = tmp_path / "rec.npz"
    np.savez(npz, t=walk.t, accel=walk.accel, axis_names=np.array(["x", "y"]))
    for path, extra in ((gz, ["--axis", "ax", "--axis", "ay"]), (npz, [])):
        status, _, err = _run(["filter", path, "--model", FOOT, *extra, "--out", tmp_path / "f.npz"], capsys)
        assert status == 0, err


def _refusal(tmp_path, capsys, lines, *extra, model=FOOT):
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    argv = [
        "smooth",
        path,
        "--model",
        model,
        "--axis",
        "ax",
        "--axis",
        "ay",
        "--full",
        *extra,
        "--out",
        tmp_path / "o.npz",
    ]
    status, _, err = _run(argv, capsys)
    assert status == 2 and err.startswith("accelnav: error: ") and err.count("\n") == 1, err
    assert not (tmp_path / "o.npz").exists()
    return err


def test_wrong_rate_is_refused_naming_both_rates(tmp_path, capsys, walk):
    err = _refusal(
        tmp_path, capsys, _csv_lines(walk.t, walk.accel), "--unit", "m/s^2", model=MODELS / "adxl250_default.toml"
    )
    assert "sampled at 200 Hz" in err and "rate_hz = 100 Hz" in err


def test_milliseconds_are_named(tmp_path, capsys, walk):
    err = _refusal(tmp_path, capsys, _csv_lines(walk.t * 1000.0, walk.accel))
    assert "looks like milliseconds" in err and "t_ms" in err
    # named as such, it is read
    path = tmp_path / "ms.csv"
    path.write_text("\n".join(_csv_lines(walk.t * 1000.0, walk.accel, "t_ms")) + "\n")
    argv = ["filter", path, "--model", FOOT, "--axis", "ax", "--axis", "ay", "--out", tmp_path / "f.npz"]
    assert _run(argv, capsys)[0] == 0


def test_gap_is_refused_with_its_line_or_filled_predict_only(tmp_path, capsys, walk):
    lines = _csv_lines(walk.t, walk.accel)
    holed = lines[:1001] + lines[1201:]  # a 1 s hole: rows 1000..1199 (lines 1002..1201) removed
    err = _refusal(tmp_path, capsys, holed)
    assert "gap in time of 1.005 s" in err and "line 1001" in err
    path = tmp_path / "holed.csv"
    path.write_text("\n".join(holed) + "\n")
    argv = [
        "smooth",
        path,
        "--model",
        FOOT,
        "--axis",
        "ax",
        "--axis",
        "ay",
        "--allow-gaps",
        "--full",
        "--out",
        tmp_path / "o.npz",
    ]
    status, out, err = _run(argv, capsys)
    assert status == 0, err
    assert "200 missing samples filled in (predict only)" in out
    arrays, _ = load_run(tmp_path / "o.npz")
    assert len(arrays["t"]) == len(walk.t)
    assert arrays["clipped"][1000:1200].all() and not arrays["clipped"][:1000].any()
    np.testing.assert_allclose(arrays["t"], walk.t, atol=1e-6)


def test_ragged_row_is_refused_with_its_line(tmp_path, capsys, walk):
    lines = _csv_lines(walk.t, walk.accel)
    lines[500] += ",0.5"
    err = _refusal(tmp_path, capsys, lines)
    assert "line 501: 4 fields; the header has 3" in err


def test_nan_and_backwards_time_are_refused_with_their_line(tmp_path, capsys, walk):
    lines = _csv_lines(walk.t, walk.accel)
    lines[300] = lines[300].rsplit(",", 1)[0] + ",nan"
    assert "sample 299 (line 301) is not a number" in _refusal(tmp_path, capsys, lines)
    lines = _csv_lines(walk.t, walk.accel)
    lines[400], lines[401] = lines[401], lines[400]
    assert "time does not increase at sample 400 (line 402)" in _refusal(tmp_path, capsys, lines)


def test_axis_count_must_match_the_model(tmp_path, capsys, walk):
    # "ax" is the model's axis x now (issue 25), and naming one model axis narrows the model to it;
    # a column that is no model axis still has to match the model's count
    path = tmp_path / "one.csv"
    lines = _csv_lines(walk.t, walk.accel)
    path.write_text("\n".join(["t,acc_p,acc_q", *lines[1:]]) + "\n")
    argv = ["filter", path, "--model", FOOT, "--axis", "acc_p", "--out", tmp_path / "f.npz"]
    status, _, err = _run(argv, capsys)
    assert status == 2 and "1 axes (acc_p) for the model's 2 (x, y)" in err


def test_fit_bias_refuses_a_ragged_row_too(tmp_path, capsys):
    t = np.arange(8000) / 100.0
    lines = ["t_s,acc_x_g"] + [f"{x:.2f},{0.01:.4f}" for x in t]
    lines[4000] += ",7"
    (tmp_path / "r.csv").write_text("\n".join(lines) + "\n")
    status, _, err = _run(["fit-bias", tmp_path / "r.csv", "--out", tmp_path / "m.toml"], capsys)
    assert status == 2 and "line 4001: 3 fields; the header has 2" in err


def test_jittery_timing_is_refused(tmp_path, capsys, walk):
    # a clock that wanders by half a period, slowly (no step is a gap, the median rate is right)
    t = walk.t + 0.5 * 0.005 * np.sin(2 * np.pi * np.arange(len(walk.t)) / 400)
    err = _refusal(tmp_path, capsys, _csv_lines(t, walk.accel))
    assert "timing jitters too much" in err
