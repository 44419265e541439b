"""A phone logger's export from file to track with one command: ``accelnav smooth`` levels it through the library's
reader (and says so with the levelling's summary), ``accelnav level`` keeps the levelled recording, which
``smooth`` reads to the same track; ``fit-bias`` takes an IMU log the same way."""

from __future__ import annotations

import numpy as np
import pytest
from support import phone_logs as pl
from support.cli import run_cli

import accelnav
from accelnav.level import G

FOOT = accelnav.example_path("foot_imu.toml")  # level axes x, y at 200 Hz: the simulated phone's rate


@pytest.fixture(scope="module")
def phone():
    return pl.phone()


def _end(path) -> np.ndarray:
    run, _ = accelnav.load_run(path)
    return run.position()[-1]


@pytest.mark.parametrize("layout", ["sensor-logger zip", "sensor-logger folder", "sensorlog csv"])
def test_smooth_takes_a_phone_export_to_a_track(layout, phone, tmp_path, capsys):
    if layout == "sensor-logger zip":
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
    assert "by the recording's own orientation" in said and "axes x, y" in said
    np.testing.assert_allclose(_end(tmp_path / "o.npz"), pl.MOVE, atol=0.03)  # metres, of a 1.1 m move


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


def test_fit_bias_levels_a_still_imu_log(tmp_path, capsys):
    rng = np.random.default_rng(4)
    n = 70 * 200
    t = np.arange(n) / 200.0
    tilt = np.radians(15.0)
    f = np.tile([0.0, G * np.sin(tilt), G * np.cos(tilt)], (n, 1)) + rng.normal(0, 0.02, (n, 3))
    w = rng.normal(0, 0.002, (n, 3))
    rows = "\n".join(",".join(f"{v:.7g}" for v in (t[k], *f[k], *w[k])) for k in range(n))
    src = tmp_path / "still.csv"
    src.write_text("t,ax_m_s2,ay_m_s2,az_m_s2,gx_rad_s,gy_rad_s,gz_rad_s\n" + rows + "\n")
    status, out, err = run_cli(["fit-bias", src, "--model", FOOT, "--out", tmp_path / "m.toml"], capsys)
    assert status == 0, err
    assert any("levelled (" in line and "Fusion" in line for line in out.splitlines()), out


def test_imu_log_refusals_are_one_line(phone, tmp_path, capsys):
    src = pl.sensor_logger_zip(tmp_path / "rec.zip", phone)
    args = ["smooth", src, "--model", FOOT, "--time-column", "t", "--out", tmp_path / "o.npz"]
    status, _, err = run_cli(args, capsys)
    assert status == 2 and "whose format says its clocks" in err and err.count("\n") == 1
    plain = tmp_path / "plain.csv"
    plain.write_text("t,acc_x_g\n0,0\n0.01,0\n")
    status, _, err = run_cli(["level", plain, "--out", tmp_path / "l.csv"], capsys)
    assert status == 2 and "not an IMU log" in err and err.count("\n") == 1
