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
    # R: datasheet noise over the one-pole filter's noise bandwidth plus the ADC step's rounding; the
    # noisiest axis (Z, 300 ug/sqrt(Hz)) sets the one R of the model
    step = 3.3 / 1024 / a.sensitivity_v_per_g * G0
    expect = (300e-6 * G0) ** 2 * 50 * np.pi / 2 + step**2 / 12
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


def _asked(monkeypatch, answers: dict[str, str]):
    """A terminal on stdin whose user answers each prompt (matched by its start) from ``answers``."""
    import builtins
    import sys

    asked = []

    def answer(prompt=""):
        asked.append(prompt)
        return next(v for k, v in answers.items() if prompt.startswith(k))

    monkeypatch.setattr(sys.stdin, "isatty", lambda: True, raising=False)
    monkeypatch.setattr(builtins, "input", answer)
    return asked


def test_init_answers_and_flags_give_the_same_model(tmp_path, monkeypatch, capsys):
    """The supply answered at the prompt scales the ratiometric sensitivity exactly as --supply does."""
    flags = tmp_path / "flags.toml"
    assert main([*INIT, "--adc-ref", "5", "--name", "m", "--out", str(flags)]) == 0
    asked = _asked(monkeypatch, {"supply": "3.3", "ADC bits": "10", "sample rate": "100"})
    answered = tmp_path / "asked.toml"
    assert main(["init", "--part", "adxl335", "--adc-ref", "5", "--name", "m", "--out", str(answered)]) == 0
    assert len(asked) == 3  # supply, bits and rate were asked, not taken from anywhere else
    assert answered.read_text() == flags.read_text()
    assert load_model(answered).sensor.analog.sensitivity_v_per_g == pytest.approx(0.33)


@pytest.mark.parametrize(
    ("extra", "key", "said"),
    [
        (["--supply", "5"], "supply_v", "the ADXL335 runs on 1.8 to 3.6 V"),
        (["--supply", "1.5"], "supply_v", "the ADXL335 runs on 1.8 to 3.6 V"),
        (["--supply", "3.3", "--range-g", "8"], "range_g", "the ADXL335 measures +-3.6 g"),
    ],
)
def test_init_refuses_what_the_parts_datasheet_does_not_allow(tmp_path, capsys, extra, key, said):
    out = tmp_path / "m.toml"
    argv = ["init", "--part", "adxl335", "--adc-bits", "10", "--rate", "100", *extra, "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"init: {key}:" in err and said in err, err
    assert not out.exists()


def test_init_supply_refused_for_the_part_even_when_answered(tmp_path, monkeypatch, capsys):
    _asked(monkeypatch, {"supply": "5", "ADC bits": "10", "sample rate": "100"})
    assert main(["init", "--part", "adxl335", "--out", str(tmp_path / "m.toml")]) == 2
    assert "the ADXL335 runs on 1.8 to 3.6 V" in capsys.readouterr().err


@pytest.mark.parametrize(("axes", "density"), [("x,y,z", 300e-6), ("x,y", 150e-6), ("z", 300e-6)])
def test_init_R_is_the_variance_of_the_noisiest_axis(tmp_path, axes, density):
    """R computed apart from accelnav: the one-pole output filter's noise power integrated over frequency
    (d^2 / (1 + (f/B)^2) from 0 to infinity), plus a uniform rounding error over one ADC step."""
    from scipy.integrate import quad

    out = tmp_path / "m.toml"
    assert main([*INIT, "--adc-ref", "5", "--axes", axes, "--out", str(out)]) == 0
    m = load_model(out)
    bw = 50.0
    power, _ = quad(lambda f: (density * G0) ** 2 / (1 + (f / bw) ** 2), 0, np.inf)
    step = 5.0 / 2**10 / 0.33 * G0  # 5 V reference, 10 bits, 0.33 V/g at 3.3 V
    rounding = np.mean((np.linspace(-0.5, 0.5, 200001) * step) ** 2)
    assert m.noise.R == pytest.approx(power + rounding, rel=1e-4)
    assert m.sensor.noise_density_g_rthz == density  # R follows from the file's own keys


def test_init_asks_to_record_what_the_model_is_proved_for(tmp_path, capsys):
    out = tmp_path / "m.toml"
    assert main([*INIT, "--out", str(out)]) == 0
    said = capsys.readouterr().out
    import re

    minutes = re.search(r"record the part still for ([0-9.]+) min \(([0-9.]+) s", said)
    assert minutes, said
    run = load_model(out).ranges.max_run_s
    assert float(minutes.group(1)) * 60 == run and float(minutes.group(2)) == run
    assert "or more" not in said


def test_a_noise_density_given_replaces_the_parts_per_axis_figures(tmp_path):
    out = tmp_path / "m.toml"
    assert main([*INIT, "--noise-density", "200e-6", "--out", str(out)]) == 0
    m = load_model(out)
    assert m.sensor.noise_density_g_rthz == 200e-6  # the one figure given, for every axis (z's 300 dropped)
    assert "Noise density per axis" not in out.read_text()
