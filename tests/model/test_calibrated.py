"""The calibrated sensor kind: data already in g or m/s^2, for the host tools (issue #11)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MODELS

from accelnav.hil_sim.sim.sensor import SimRun, simulate
from accelnav.model.design import input_conversion
from accelnav.model.load import G0, ModelError, load_model, loads_model

FOOT = MODELS / "foot_imu.toml"


def test_shipped_calibrated_model_needs_no_read_out_constants():
    m = load_model(FOOT)
    assert m.sensor.kind == "calibrated" and m.sensor.analog is None and m.sensor.duty_cycle is None
    assert m.sensor.calibrated.unit == "m/s^2" and m.rate_hz == 200.0
    conv = input_conversion(m, "x")
    assert conv.accel(np.array([1.5]))[0] == 1.5
    assert conv.clipped(np.array([0.0, np.nan, 16 * G0, -16 * G0])).tolist() == [False, True, True, True]


@pytest.mark.parametrize(
    "old,new,key",
    [
        ('unit = "m/s^2" ', 'unit = "volts" ', "sensor.calibrated.unit"),
        ("lsb_per_g = 2048.0", "lsb_per_g = -1.0", "sensor.calibrated.lsb_per_g"),
        ('name = "x"\n', 'name = "x"\nsensitivity_v_per_g = 0.038\n', "axes[0].sensitivity_v_per_g"),
        ("[sensor.calibrated]", "[sensor.analog]\nsupply_v = 5.0\n\n[sensor.calibrated]", "sensor.analog"),
    ],
)
def test_bad_calibrated_models_refused_in_one_line(old, new, key):
    text = FOOT.read_text()
    assert text.count(old) == 1
    with pytest.raises(ModelError) as exc:
        loads_model(text.replace(old, new), source="bad.toml")
    assert str(exc.value).startswith(f"bad.toml: {key}: ") and "\n" not in str(exc.value)


def test_g_unit_scales_by_g0():
    m = loads_model(FOOT.read_text().replace('unit = "m/s^2" ', 'unit = "g" '), source="g.toml")
    assert input_conversion(m, 0).accel(np.array([2.0]))[0] == pytest.approx(2 * G0)


def test_simulated_calibrated_run_round_trips_and_is_quantised():
    m = load_model(FOOT)
    run = simulate(m, "walking", 5.0, 3)
    assert run.code is None and run.t1 is None
    lsb = G0 / 2048.0
    q = run.accel / lsb
    assert np.allclose(q, np.rint(q), atol=1e-6)
    back = SimRun.from_arrays(m, run.to_arrays())
    assert np.array_equal(back.accel, run.accel) and np.array_equal(back.stance, run.stance)


def test_codegen_refuses_a_calibrated_sensor_in_one_line(capsys, tmp_path):
    from accelnav.cli import main

    assert main(["codegen", str(FOOT), "--out", str(tmp_path / "gen")]) == 2
    err = capsys.readouterr().err
    assert "sensor.kind: 'calibrated'" in err and err.count("\n") == 1
    assert not (tmp_path / "gen").exists() or not any((tmp_path / "gen").iterdir())
