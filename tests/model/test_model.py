"""The model file: loading, derived numbers, and one-line refusals of bad files."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import MODELS, edited_model, model_text

from accelnav.cli import main
from accelnav.model.design import axis_design, input_conversion, process_noise
from accelnav.model.load import G0, ModelError, load_model, loads_model


def test_default_model_loads(default_model):
    m = default_model
    assert m.sensor.kind == "analog" and m.sensor.analog.adc_bits == 12
    assert [a.name for a in m.axes] == ["x", "y"]
    assert m.Ts == pytest.approx(0.01)
    assert m.axis("y").zero_g == 2.501  # per-axis override
    assert m.axis("x").zero_g == 2.5  # falls back to the sensor's value
    assert len(m.sha256) == 64
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.rate_hz = 1.0


def test_every_shipped_model_loads():
    paths = sorted(MODELS.glob("*.toml"))
    assert len(paths) >= 2
    for p in paths:
        assert load_model(p).axes


def test_design_numbers(default_model):
    d = axis_design(default_model, "x")
    Ts, T = 0.01, 300.0
    assert d.phi == pytest.approx(T / (T + Ts), rel=1e-15)
    assert d.b[3] == pytest.approx(Ts * (0.08 + 0.05) / (T + Ts), rel=1e-15)
    # the bias recursion's fixed point is c1 + c2
    assert d.b[3] / (1 - d.phi) == pytest.approx(0.13, rel=1e-12)
    assert d.F[0, 2] == pytest.approx(Ts**2 / 2)
    assert np.array_equal(d.H, [[0, 0, 1, 1]])
    Q = process_noise(Ts, 1.0, 1e-3)
    assert np.allclose(Q, Q.T) and np.all(np.linalg.eigvalsh(Q) >= 0)
    assert Q[3, 3] == pytest.approx(Ts * 1e-6)
    with pytest.raises(ValueError):
        d.F[0, 0] = 2.0  # design arrays are read-only


def test_analog_conversion_is_exact_at_zero_g(default_model):
    conv = input_conversion(default_model, "x")
    # 2.5 V on a 5 V, 12-bit ADC is code 2048 exactly
    assert conv.accel(2048) == pytest.approx(0.0, abs=1e-12)
    # one LSB is 5/4096 V = 1.2207 mV, i.e. 1.2207/38 g
    assert conv.scale == pytest.approx(5 / 4096 / 0.038 * G0, rel=1e-12)
    assert conv.clipped(np.array([0, 1, 4094, 4095])).tolist() == [True, False, False, True]


def test_duty_conversion(duty_model):
    conv = input_conversion(duty_model, "x")
    t2 = duty_model.sensor.duty_cycle.t2_counts
    assert t2 == 40000
    assert conv.accel(t2 // 2, t2) == pytest.approx(0.0)
    assert conv.accel(int(t2 * 0.625), t2) == pytest.approx(G0)
    assert conv.clipped([0, 100, t2, 100], [t2, t2, t2, 0]).tolist() == [True, False, True, True]
    assert conv.clipped([100], [int(t2 * 1.5)]).tolist() == [True]  # period far off nominal


def test_missing_file_is_one_line(tmp_path):
    with pytest.raises(ModelError) as exc:
        load_model(tmp_path / "nope.toml")
    assert "nope.toml" in str(exc.value) and "no such file" in str(exc.value)


# Each bad file: (edits to the default model, key the message must name, words it must contain)
BAD_FILES = {
    "syntax": ([("[sampling]", "[sampling")], "(syntax)", "not valid TOML"),
    "missing table": ([("[sampling]\nrate_hz = 100.0", "")], "sampling", "required"),
    "missing key": ([("rate_hz = 100.0", "")], "sampling.rate_hz", "required"),
    "unknown key": ([("rate_hz = 100.0", "rate_hz = 100.0\nrat_hz = 5")], "sampling.rat_hz", "unknown key"),
    "string for number": ([("rate_hz = 100.0", 'rate_hz = "100"')], "sampling.rate_hz", "expected a number"),
    "zero rate": ([("rate_hz = 100.0", "rate_hz = 0.0")], "sampling.rate_hz", "accepted"),
    "bad kind": ([('kind = "analog"', 'kind = "digital"')], "sensor.kind", "'duty_cycle'"),
    "adc bits": ([("adc_bits = 12", "adc_bits = 40")], "sensor.analog.adc_bits", "from 6 to 24"),
    "float adc bits": ([("adc_bits = 12", "adc_bits = 12.5")], "sensor.analog.adc_bits", "integer"),
    "negative T": ([("T = 300.0", "T = -300.0")], "axes[0].T", "accepted"),
    "negative R": ([("R = 0.0160", "R = -1.0")], "noise.R", "accepted"),
    "nan sigma": ([("sigma_n = 1.0", "sigma_n = nan")], "noise.sigma_n", "finite"),
    "duplicate axes": ([('name = "y"', 'name = "x"')], "axes", "must differ"),
    "axis name": ([('name = "y"', 'name = "y axis"')], "axes[1].name", "identifier"),
    "no axes": (
        [('[[axes]]\nname = "x"', '[[axis]]\nname = "x"'), ('[[axes]]\nname = "y"', '[[axis]]\nname = "y"')],
        "axes",
        "required",
    ),
    "initial sigma": (
        [("initial_sigma = [0.0, 0.0, 0.05, 0.05]", "initial_sigma = [0.0, 0.05]")],
        "filter.initial_sigma",
        "4 numbers",
    ),
    "bad form": ([('form = "covariance"', 'form = "information"')], "filter.form", "'gain_schedule'"),
    "zero-g above ref": ([("zero_g_v = 2.5 ", "zero_g_v = 5.5 ")], "sensor.analog.zero_g_v", "reference"),
    "duty table on analog": (
        [("[sampling]", "[sensor.duty_cycle]\nduty_per_g = 0.1\n\n[sampling]")],
        "sensor.duty_cycle",
        "kind is 'analog'",
    ),
    "bias beyond full scale": ([("c2 = 0.05", "c2 = 600.0")], "axes[0].c1", "full scale"),
    "full scale beyond ADC": (
        [("sensitivity_v_per_g = 0.038", "sensitivity_v_per_g = 0.06")],
        "axes[0].sensitivity_v_per_g",
        "outside the read-out's 0..5",
    ),
    "max run": ([("max_run_s = 3600.0", "max_run_s = 0")], "ranges.max_run_s", "accepted"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_model_refused_naming_the_key(case):
    edits, key, words = BAD_FILES[case]
    with pytest.raises(ModelError) as exc:
        edited_model(edits)
    msg = str(exc.value)
    assert msg.startswith("bad.toml: "), msg
    assert exc.value.key == key, msg
    assert f": {key}: " in msg, msg
    assert words in msg, msg
    assert "\n" not in msg


def test_duty_model_refusals():
    base = MODELS / "adxl202_duty.toml"
    # T2 shorter than 16 timer counts cannot resolve anything
    with pytest.raises(ModelError, match=r"sensor\.duty_cycle\.t2_period_s: gives only 8 timer counts"):
        edited_model([("t2_period_s = 0.005", "t2_period_s = 0.000001")], base=base)
    # a PWM period longer than the sample period cannot give one capture per sample
    with pytest.raises(ModelError, match=r"sensor\.duty_cycle\.t2_period_s: .* longer than the sample period"):
        edited_model([("t2_period_s = 0.005", "t2_period_s = 0.05")], base=base)


def test_axis_lookup(default_model):
    assert default_model.axis(1).name == "y" and default_model.axis("x").name == "x"
    for bad in (2, -1, "z"):
        with pytest.raises(ModelError, match="axes: no axis"):
            default_model.axis(bad)


def test_not_utf8():
    with pytest.raises(ModelError, match=r"\(file\): not UTF-8"):
        loads_model(b"\xff\xfe[model]", source="bin.toml")


def test_cli_prints_one_line_not_a_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(model_text().replace("adc_bits = 12", "adc_bits = 99"))
    status = main(["sim", "--model", str(bad), "--out", str(tmp_path / "x.npz")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "sensor.analog.adc_bits" in err and str(bad) in err


def test_a_text_is_parsed_once_per_source_and_an_edit_is_read_again(tmp_path):
    """A fleet loads the same model for every input: parsed once (the Model is immutable, one object serves
    all); the same text under another name, an edited file and a bad file are each read as they are."""
    path = tmp_path / "m.toml"
    path.write_text(model_text())
    first = load_model(path)
    assert load_model(path) is first
    assert loads_model(model_text(), source="other.toml") is not first
    path.write_text(model_text().replace("rate_hz = 100.0", "rate_hz = 50.0"))
    assert load_model(path).rate_hz == 50 and first.rate_hz == 100
    path.write_text(model_text().replace("adc_bits = 12", "adc_bits = 99"))
    for _ in range(2):
        with pytest.raises(ModelError, match="adc_bits"):
            load_model(path)


def test_model_hash_tracks_content():
    a = loads_model(model_text(), source="a.toml")
    b = loads_model(model_text() + "\n# a comment\n", source="b.toml")
    assert a.sha256 != b.sha256
    assert dataclasses.replace(a, source="b.toml", sha256=b.sha256) == b  # same meaning
    assert math.isclose(a.max_accel_m_s2, 50 * G0)
