"""accelnav init for an ADXL335-class part, and the chain a new user runs next on simulated counts:
init -> fit-bias (raw counts) -> smooth --unit counts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from accelnav.cli import main
from accelnav.model.edit import revalidate
from accelnav.model.load import G0, load_model

sensor = pytest.importorskip("accelnav.hil_sim.sim.sensor")

INIT = ["init", "--part", "adxl335", "--supply", "3.3", "--adc-bits", "10", "--rate", "100"]
# the widest output filter the datasheet allows on X and Y (Cx 0.003 uF): 7.5 mg rms of noise, a quarter of the
# 10-bit step, dithers the ADC enough for fit-bias; at 50 Hz (1.3 mg) the still signal sits on one code
WIDE = ["--bandwidth", "1600"]


def _write_counts(path, run, names):
    cols = ["t"] + [f"acc_{n}_counts" for n in names]
    data = np.column_stack([run.t, run.code])
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt=["%.6f"] + ["%d"] * len(names))


def test_init_writes_a_commented_model_that_loads(tmp_path, capsys):
    out = tmp_path / "adxl335.toml"
    assert main([*INIT, "--out", str(out)]) == 0
    m = load_model(out)
    a = m.sensor.analog
    assert (m.sensor.kind, a.adc_bits, a.supply_v, a.adc_ref_v, m.rate_hz) == ("analog", 10, 3.3, 3.3, 100.0)
    assert [x.name for x in m.axes] == ["x", "y", "z"]
    assert a.sensitivity_v_per_g == pytest.approx(0.3 * 3.3 / 3.0) and a.zero_g_v == pytest.approx(1.65)
    # R: datasheet noise over the one-pole filter's noise bandwidth plus the ADC step's rounding
    step = 3.3 / 1024 / a.sensitivity_v_per_g * G0
    expect = (150e-6 * G0) ** 2 * 50 * np.pi / 2 + step**2 / 12
    assert m.noise.R == pytest.approx(expect, rel=1e-5)
    text = out.read_text()
    assert "ADXL335 datasheet" in text and "placeholders" in text
    said = capsys.readouterr().out
    assert "accelnav fit-bias" in said and "accelnav calibrate" in said


def test_init_without_a_terminal_names_what_is_missing(tmp_path, capsys):
    assert main(["init", "--kind", "analog", "--rate", "100", "--out", str(tmp_path / "m.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--supply" in err and "--adc-bits" in err and "--sensitivity" in err
    assert not (tmp_path / "m.toml").exists()


def test_init_refuses_a_part_the_loader_refuses(tmp_path, capsys):
    # 0.5 V/g x 3.6 g around 1.65 V leaves the 0..3.3 V read-out: the loader's own one-line refusal
    assert main([*INIT, "--sensitivity", "0.5", "--out", str(tmp_path / "m.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "outside the read-out" in err
    assert not (tmp_path / "m.toml").exists()


def test_chain_init_fit_bias_smooth_counts(tmp_path, capsys):
    described = tmp_path / "adxl335.toml"
    assert main([*INIT, *WIDE, "--out", str(described)]) == 0
    # the part as it really is: a warm-up bias the datasheet does not give
    real = load_model(described)
    biased = [dataclasses.replace(a, c1=0.3 - 0.1 * j, c2=0.2 * (j - 1), T=60.0) for j, a in enumerate(real.axes)]
    real = revalidate(dataclasses.replace(real, axes=tuple(biased)))
    still = sensor.simulate(real, "stationary", 300.0, seed=2)
    _write_counts(tmp_path / "still.csv", still, "xyz")
    fitted = tmp_path / "fitted.toml"
    code = main(["fit-bias", str(tmp_path / "still.csv"), "--model", str(described), "--out", str(fitted)])
    assert code == 0, capsys.readouterr().err
    fit = load_model(fitted)
    step = 3.3 / 1024 / real.sensor.analog.sensitivity_v_per_g * G0  # the ADC step, m/s^2
    for got, true in zip(fit.axes, real.axes, strict=True):
        assert abs((got.c1 + got.c2) - (true.c1 + true.c2)) < step / 2, got.name  # within the rounding
    move = sensor.simulate(real, "vehicle", 60.0, seed=3)
    _write_counts(tmp_path / "move.csv", move, "xyz")
    out = tmp_path / "move.npz"
    code = main(
        ["smooth", str(tmp_path / "move.csv"), "--model", str(fitted), "--unit", "counts", "--full", "--out", str(out)]
    )
    assert code == 0, capsys.readouterr().err
    with np.load(out) as z:
        accel = z["accel"]
    np.testing.assert_array_equal(accel, move.accel)  # the model's own conversion of the counts
