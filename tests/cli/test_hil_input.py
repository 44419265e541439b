"""accelnav hil --input: a user's own recording (no truth) through SIL and PIL, raw counts fed as they are."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from conftest import MODELS

from accelnav.cli import main
from accelnav.model.load import G0, load_model

sensor = pytest.importorskip("accelnav.hil_sim.sim.sensor")
hil = pytest.importorskip("accelnav.hil_sim.targets.hil")

needs_pil = pytest.mark.skipif(
    shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None,
    reason="qemu-system-arm or arm-none-eabi-gcc not installed",
)


def _write(path, t, cols: dict[str, np.ndarray], fmt: str) -> None:
    data = np.column_stack([t, *cols.values()])
    header = ",".join(["t", *cols])
    np.savetxt(path, data, delimiter=",", header=header, comments="", fmt=["%.6f"] + [fmt] * len(cols))


@pytest.fixture(scope="module")
def sim():
    return sensor.simulate(load_model(MODELS / "adxl250_default.toml"), "stop_and_go", 8.0, seed=4)


def test_counts_are_fed_as_they_are(tmp_path, sim):
    path = tmp_path / "rec.csv"
    _write(path, sim.t, {"acc_x_counts": sim.code[:, 0], "acc_y_counts": sim.code[:, 1]}, "%d")
    rec, model = hil.recorded_input(path, MODELS / "adxl250_default.toml")
    np.testing.assert_array_equal(rec.code, sim.code)
    np.testing.assert_array_equal(rec.accel, sim.accel)  # the firmware's conversion, as the simulator's
    np.testing.assert_array_equal(rec.clipped, sim.clipped)
    assert rec.r is None and model.name == "adxl250_default"


def test_acceleration_in_g_is_read_out_as_the_sensor_would(tmp_path, sim):
    path = tmp_path / "rec_g.csv"
    _write(path, sim.t, {"acc_x_g": sim.accel[:, 0] / G0, "acc_y_g": sim.accel[:, 1] / G0}, "%.12g")
    rec, _ = hil.recorded_input(path, MODELS / "adxl250_default.toml")
    np.testing.assert_array_equal(rec.code, sim.code)  # the read-out inverts the conversion


def test_duty_cycle_recording_gets_nominal_periods(tmp_path):
    model = load_model(MODELS / "adxl202_duty.toml")
    run = sensor.simulate(model, "stop_and_go", 4.0, seed=5)
    path = tmp_path / "duty.csv"
    _write(path, run.t, {f"acc_{n}_g": run.accel[:, j] / G0 for j, n in enumerate(run.axis_names)}, "%.12g")
    rec, _ = hil.recorded_input(path, MODELS / "adxl202_duty.toml")
    assert rec.code is None and (rec.t2 == model.sensor.duty_cycle.t2_counts).all()
    step = G0 / (model.sensor.duty_cycle.t2_counts * model.axes[0].sensitivity)  # one T1 count, m/s^2
    assert np.abs(rec.accel - run.accel).max() <= step  # the jitter of T2 moved the simulated read-out


def test_hil_input_sil_has_no_truth_rows(tmp_path, sim, capsys):
    path = tmp_path / "rec.csv"
    _write(path, sim.t, {"acc_x_counts": sim.code[:, 0], "acc_y_counts": sim.code[:, 1]}, "%d")
    code = main(["hil", "--input", str(path), "--model", str(MODELS / "adxl250_default.toml"), "--unit", "counts"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert f"recording {path}, {len(sim.t)} samples" in out
    assert "within the generator's stated bound" in out
    assert "rms [m]" not in out  # no truth, no position-error table


def test_hil_input_refuses_simulation_options_in_one_line(tmp_path, sim, capsys):
    path = tmp_path / "rec.csv"
    _write(path, sim.t, {"acc_x_counts": sim.code[:, 0], "acc_y_counts": sim.code[:, 1]}, "%d")
    assert main(["hil", "--input", str(path), "--scenario", "vehicle"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--scenario" in err and "--input" in err
    assert main(["hil", "--unit", "counts"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--unit" in err and "only with --input" in err


@needs_pil
def test_hil_input_pil_equals_sil_bit_for_bit(tmp_path, sim, capsys):
    path = tmp_path / "rec.csv"
    _write(path, sim.t, {"acc_x_counts": sim.code[:, 0], "acc_y_counts": sim.code[:, 1]}, "%d")
    args = ["hil", "--input", str(path), "--unit", "counts", "--target", "pil", "--out", str(tmp_path / "pil")]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert f"PIL vs SIL: {len(sim.t)} sample rows, bit-identical" in out
    assert list((tmp_path / "pil").glob("pil_mps2_an385_adxl250_default_rec.acnlog"))
