"""The chain of issue 25 for an ADXL335-class part described from scratch, on simulated raw counts:
init -> fit-bias -> calibrate -> codegen -> hil --input -> smooth --unit counts.

The part as it really is differs from its description: a warm-up bias, zero-g off by some mV and
sensitivities off by a few %. Each step must find what the step before left out."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

from accelnav.cli import main
from accelnav.model.design import input_conversion
from accelnav.model.edit import revalidate
from accelnav.model.load import G0, load_model

sensor = pytest.importorskip("accelnav.hil_sim.sim.sensor")
hil = pytest.importorskip("accelnav.hil_sim.targets.hil")
from accelnav.hil_sim.sim.trajectories import TUMBLE_HOLD_S, TUMBLE_TURN_S, tumble_poses  # noqa: E402

INIT = ["init", "--part", "adxl335", "--supply", "3.3", "--adc-bits", "10", "--rate", "100"]
WIDE = ["--bandwidth", "1600"]  # noise enough to dither the 10-bit ADC (see test_init_new_part.py)
ZERO_MV = (15.0, -10.0, 5.0)  # the real part's zero-g offset from the datasheet's, per axis
SCALE = (1.02, 0.98, 1.01)  # and its sensitivity over the datasheet's
PIL = shutil.which("qemu-system-arm") is not None and shutil.which("arm-none-eabi-gcc") is not None


def _write_counts(path, run):
    cols = ["t"] + [f"acc_{n}_counts" for n in run.axis_names]
    data = np.column_stack([run.t, run.code])
    fmt = ["%.6f"] + ["%d"] * run.code.shape[1]
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt=fmt)


def _ok(argv, capsys) -> str:
    code = main(argv)
    out = capsys.readouterr()
    assert code == 0, f"{argv[0]}: {out.err}"
    return out.out


def test_init_fit_bias_calibrate_codegen_hil_smooth_on_counts(tmp_path, capsys):
    described = tmp_path / "adxl335.toml"
    _ok([*INIT, *WIDE, "--out", str(described)], capsys)
    nominal = load_model(described)
    real_axes = [
        dataclasses.replace(
            a, zero_g=a.zero_g + ZERO_MV[j] * 1e-3, sensitivity=a.sensitivity * SCALE[j], c1=0.3 - 0.1 * j, c2=0.0
        )
        for j, a in enumerate(nominal.axes)
    ]
    real = revalidate(dataclasses.replace(nominal, axes=tuple(real_axes)))
    settled = [a.c1 + a.c2 for a in real.axes]

    # fit-bias: a still recording from power-on
    warm = revalidate(dataclasses.replace(real, axes=tuple(dataclasses.replace(a, T=60.0) for a in real.axes)))
    _write_counts(tmp_path / "still.csv", sensor.simulate(warm, "stationary", 300.0, seed=2))
    fitted = tmp_path / "fitted.toml"
    _ok(["fit-bias", str(tmp_path / "still.csv"), "--model", str(described), "--out", str(fitted)], capsys)

    # calibrate: the six-position tumble, recorded once the part has warmed up (its bias settled)
    still_bias = [dataclasses.replace(a, c1=0.0, c2=s) for a, s in zip(real.axes, settled, strict=True)]
    warmed = revalidate(dataclasses.replace(real, axes=tuple(still_bias)))
    seconds = len(tumble_poses(3)) * (TUMBLE_HOLD_S + TUMBLE_TURN_S)
    tumble = sensor.simulate(warmed, "tumble", seconds, seed=6, initial_random=False)  # bias at its settled value
    _write_counts(tmp_path / "tumble.csv", tumble)
    calibrated = tmp_path / "calibrated.toml"
    said = _ok(["calibrate", str(tmp_path / "tumble.csv"), "--model", str(fitted), "--out", str(calibrated)], capsys)
    assert "6 still poses" in said
    cal = load_model(calibrated)
    for got, true, bias in zip(cal.axes, real.axes, settled, strict=True):
        assert got.sensitivity == pytest.approx(true.sensitivity, rel=5e-3), got.name
        # the settled bias now sits in zero-g (calibrate zeroes the bias when the calibration was recorded)
        offset = (got.zero_g - true.zero_g) / true.sensitivity * G0
        assert abs(offset - bias) < 4e-3 * G0, got.name

    # codegen: the C for the user's board; the SIL run below builds the very same text
    gen = tmp_path / "gen"
    _ok(["codegen", str(calibrated), "--out", str(gen)], capsys)
    from accelnav.hil_sim.targets.firmware import generated

    for name, text in generated(str(calibrated)).items():
        if (gen / name).exists():
            assert (gen / name).read_text() == text, name

    # hil --input: the user's own recording of a drive, as raw counts, through SIL (and PIL where it runs)
    move = sensor.simulate(real, "vehicle", 30.0, seed=3)
    _write_counts(tmp_path / "move.csv", move)
    argv = ["hil", "--input", str(tmp_path / "move.csv"), "--model", str(calibrated), "--unit", "counts"]
    if PIL:
        argv += ["--target", "pil", "--out", str(tmp_path / "pil")]
    said = _ok(argv, capsys)
    assert "within the generator's stated bound" in said and "rms [m]" not in said
    if PIL:
        assert f"PIL vs SIL: {len(move.t)} sample rows, bit-identical" in said

    # smooth --unit counts: the calibrated model's own conversion of the counts, the firmware's input
    out = tmp_path / "move.npz"
    _ok(
        [
            "smooth",
            str(tmp_path / "move.csv"),
            "--model",
            str(calibrated),
            "--unit",
            "counts",
            "--full",
            "--out",
            str(out),
        ],
        capsys,
    )
    with np.load(out) as z:
        accel = z["accel"]
    expect = np.column_stack([input_conversion(cal, j).accel(move.code[:, j]) for j in range(3)])
    np.testing.assert_array_equal(accel, expect)
    rec, _ = hil.recorded_input(tmp_path / "move.csv", calibrated, unit="counts")
    np.testing.assert_array_equal(rec.code, move.code)
    np.testing.assert_array_equal(rec.accel, accel)  # what hil fed the firmware is what smooth filtered


def test_calibrate_refuses_counts_without_their_model(tmp_path, capsys):
    described = tmp_path / "adxl335.toml"
    _ok([*INIT, "--out", str(described)], capsys)
    run = sensor.simulate(load_model(described), "tumble", 10.0, seed=1)
    _write_counts(tmp_path / "tumble.csv", run)
    assert main(["calibrate", str(tmp_path / "tumble.csv"), "--out", str(tmp_path / "c.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "counts" in err and "--model" in err
