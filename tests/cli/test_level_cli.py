"""A phone logger's export from file to track with one command: ``accelnav smooth`` levels it through the library's
reader (and says so with the levelling's summary), ``accelnav level`` keeps the levelled recording, which
``smooth`` reads to the same track; ``fit-bias`` takes an IMU log's accelerometer in the device's own axes."""

from __future__ import annotations

import numpy as np
import pytest
from support import phone_logs as pl
from support.cli import run_cli

import accelnav

FOOT = accelnav.example_path("foot_imu.toml")  # level axes x, y at 200 Hz: the simulated phone's rate


@pytest.fixture(scope="module")
def phone():
    return pl.phone()


def _end(path) -> np.ndarray:
    run, _ = accelnav.load_run(path)
    return run.position()[-1]


LAYOUTS = ["sensor-logger zip", "sensor-logger folder", "sensorlog csv", "phyphox zip", "physics toolbox csv",
           "generic csv"]  # fmt: skip


@pytest.mark.parametrize("layout", LAYOUTS)
def test_smooth_takes_a_phone_export_to_a_track(layout, phone, tmp_path, capsys):
    """With the phone's own orientation, or without one (phyphox, Physics Toolbox, a generic CSV: its gyroscope
    levels it, corrected at the rests it finds)."""
    if layout == "phyphox zip":
        src = pl.phyphox_zip(tmp_path / "rec.zip", phone)
    elif layout == "physics toolbox csv":
        src = pl.physics_toolbox_csv(tmp_path / "rec.csv", phone)
    elif layout == "generic csv":
        src = pl.generic_csv(tmp_path / "rec.csv", phone)
    elif layout == "sensor-logger zip":
        src = pl.sensor_logger_zip(tmp_path / "rec.zip", phone)
    elif layout == "sensor-logger folder":
        src = tmp_path / "rec"
        src.mkdir()
        for name, text in pl.sensor_logger_files(phone).items():
            (src / name).write_text(text)
    else:
        src = pl.sensorlog_csv(tmp_path / "rec.csv", phone)
    status, out, err = run_cli(["smooth", src, "--model", FOOT, "--zupt", "auto", "--out", tmp_path / "o.npz"], capsys)
    assert status == 0, err
    (said,) = [line for line in out.splitlines() if "levelled (" in line]
    oriented = layout.startswith(("sensor-logger", "sensorlog"))
    assert ("by the recording's own orientation" in said) == oriented and "axes x, y" in said
    np.testing.assert_allclose(_end(tmp_path / "o.npz"), pl.MOVE, atol=0.03)  # metres, of a 1.1 m move


def test_a_phones_jittering_clock_is_placed_on_the_models_grid(phone, tmp_path, capsys):
    src = pl.sensor_logger_zip(tmp_path / "rec.zip", pl.jittered(phone, 0.002))  # +-2 ms at 5 ms steps
    status, out, err = run_cli(["smooth", src, "--model", FOOT, "--zupt", "auto", "--out", tmp_path / "o.npz"], capsys)
    assert status == 0, err
    assert any("jitters" in line for line in out.splitlines()), out
    np.testing.assert_allclose(_end(tmp_path / "o.npz"), pl.MOVE, atol=0.03)


def test_level_writes_the_recording_smooth_reads(phone, tmp_path, capsys):
    src = pl.sensor_logger_zip(tmp_path / "rec.zip", phone)
    status, out, err = run_cli(["level", src, "--out", tmp_path / "level.csv"], capsys)
    assert status == 0, err
    assert "levelled 2400 samples by the recording's own orientation" in out
    assert "orientation used" in out and f"wrote {tmp_path / 'level.csv'}" in out
    assert (tmp_path / "level.csv").read_text().splitlines()[0] == "t,x_accel,y_accel,z_accel"
    horizontal = ["--axis", "x", "--axis", "y"]  # the model's two of the three level axes
    args = [
        "smooth",
        tmp_path / "level.csv",
        *horizontal,
        "--model",
        FOOT,
        "--zupt",
        "auto",
        "--out",
        tmp_path / "a.npz",
    ]
    status, _, err = run_cli(args, capsys)
    assert status == 0, err
    status, _, err = run_cli(["smooth", src, "--model", FOOT, "--zupt", "auto", "--out", tmp_path / "b.npz"], capsys)
    assert status == 0, err
    np.testing.assert_allclose(_end(tmp_path / "a.npz"), _end(tmp_path / "b.npz"), atol=2e-3)  # the CSV's digits
    np.testing.assert_allclose(_end(tmp_path / "a.npz"), pl.MOVE, atol=0.03)


def test_fit_bias_reads_an_imu_logs_accelerometer_in_the_devices_axes(tmp_path, capsys):
    """Not levelled: at rest an attitude filter aligns gravity with what the accelerometer reads, so a level
    frame would hide the very bias the fit measures; the note says so."""
    src = pl.sensor_logger_zip(tmp_path / "still.zip", pl.still(70.0))
    status, out, err = run_cli(["fit-bias", src, "--model", FOOT, "--out", tmp_path / "m.toml"], capsys)
    assert status == 0, err
    (said,) = [line for line in out.splitlines() if "not levelled" in line]
    assert "axes x, y in the device's own frame" in said
    assert "axis y (column y_device, in m/s^2)" in out
    # the device's y axis reads gravity's share of the tilt: 9.81 sin(20 deg) = 3.35 m/s^2, kept as recorded
    (c2,) = [line for line in out.splitlines() if line.startswith("  axis y: c1 = 0, c2 = ")]
    assert abs(float(c2.split("c2 = ")[1].split()[0]) - 9.80665 * np.sin(pl.TILT)) < 0.01


def test_imu_log_refusals_are_one_line(phone, tmp_path, capsys):
    src = pl.sensor_logger_zip(tmp_path / "rec.zip", phone)
    args = ["smooth", src, "--model", FOOT, "--time-column", "t", "--out", tmp_path / "o.npz"]
    status, _, err = run_cli(args, capsys)
    assert status == 2 and "whose format says its clocks" in err and err.count("\n") == 1
    plain = tmp_path / "plain.csv"
    plain.write_text("t,acc_x_g\n0,0\n0.01,0\n")
    status, _, err = run_cli(["level", plain, "--out", tmp_path / "l.csv"], capsys)
    assert status == 2 and "not an IMU log" in err and err.count("\n") == 1
