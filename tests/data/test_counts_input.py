"""Raw ADC counts in: the one reader applies the model's own read-out and calibration, as the firmware does.

An ADXL335-class part (3.3 V ratiometric, 10-bit ADC, 100 Hz, three axes) described by accelnav.model.new,
with one axis calibrated off the datasheet (zero-g, sensitivity), so the test sees the calibration applied.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from accelnav.data.inputs import read_input
from accelnav.errors import UserError
from accelnav.model.edit import revalidate
from accelnav.model.new import new_model, preset

sensor = pytest.importorskip("accelnav.hil_sim.sim.sensor")


@pytest.fixture(scope="module")
def part():
    new = new_model("adxl335_test", "analog", 100.0, ("x", "y", "z"), supply_v=3.3, adc_bits=10,
                    **{k: v for k, v in preset("adxl335", 3.3).items() if k not in ("kind", "axes")})  # fmt: skip
    m = new.model
    y = dataclasses.replace(m.axes[1], zero_g=1.62, sensitivity=0.325)  # as `calibrate` would write it
    return revalidate(dataclasses.replace(m, axes=(m.axes[0], y, m.axes[2])))


@pytest.fixture(scope="module")
def sim(part):
    return sensor.simulate(part, "vehicle", 20.0, seed=4)


def _csv(path, sim, names):
    cols = ["t"] + names
    data = np.column_stack([sim.t, sim.code[:, : len(names)]])
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt=["%.6f"] + ["%d"] * len(names))
    return path


def test_counts_match_the_simulators_conversion_and_calibration(part, sim, tmp_path):
    path = _csv(tmp_path / "rec.csv", sim, ["acc_x_counts", "acc_y_counts", "acc_z_counts"])
    run, model = read_input(path, part)
    assert model is part
    np.testing.assert_array_equal(run["accel"], sim.accel)  # the same float64 arithmetic, calibration included
    assert not np.allclose(run["accel"][:, 1], sim.code[:, 1] * (3.3 / 1024 / 0.33 * 9.80665) - 1.65 / 0.33 * 9.80665)


def test_counts_implied_by_an_analog_model_and_given_by_unit(part, sim, tmp_path):
    bare = _csv(tmp_path / "bare.csv", sim, ["acc_x", "acc_y", "acc_z"])
    run, _ = read_input(bare, part)  # no unit in the names: an analog model's samples are its ADC codes
    np.testing.assert_array_equal(run["accel"], sim.accel)
    named = _csv(tmp_path / "named.csv", sim, ["ch0", "ch1", "ch2"])
    run, _ = read_input(named, part, axes=["ch0", "ch1", "ch2"], unit="counts")
    np.testing.assert_array_equal(run["accel"], sim.accel)


def test_counts_agree_with_the_generated_c_conversion(part, sim, tmp_path):
    """The firmware's own convert() (generated C through cffi) on every code of the run, within the
    generator's stated conversion error."""
    from accelnav.codegen.emit_c import emit
    from accelnav.codegen.ranges import plan_axis
    from accelnav.hil_sim.targets.harness import build

    files = emit(part)
    mod = build(files, tmp_path)
    z = mod.ffi.new("int32_t *")
    path = _csv(tmp_path / "rec.csv", sim, ["acc_x_counts", "acc_y_counts", "acc_z_counts"])
    run, _ = read_input(path, part)
    for j, ax in enumerate(part.axes):
        p = plan_axis(part, j, part.filter.form)
        convert = getattr(mod.lib, f"accelnav_{ax.name}_convert")
        codes = np.unique(sim.code[:, j])
        c_accel = {}
        for c in codes.tolist():
            assert convert(int(c), z)
            c_accel[c] = z[0] * 2.0 ** -p.f("z")
        ours = run["accel"][:, j]
        theirs = np.array([c_accel[c] for c in sim.code[:, j].tolist()])
        assert np.max(np.abs(ours - theirs)) <= p.z_error, ax.name


def test_rail_codes_are_clipped_and_non_codes_refused(part, sim, tmp_path):
    code = sim.code.copy()
    code[5, 0] = 0
    code[6, 2] = 1023
    run, _ = read_input({"t": sim.t, "acc_x_counts": code[:, 0], "acc_y_counts": code[:, 1],
                         "acc_z_counts": code[:, 2]}, part)  # fmt: skip
    assert run["clipped"][5, 0] and run["clipped"][6, 2] and run["clipped"].sum() == 2
    code[7, 1] = 1024
    with pytest.raises(UserError, match=r"sample 7.*not an ADC code.*0\.\.1023"):
        read_input({"t": sim.t, "acc_x_counts": code[:, 0], "acc_y_counts": code[:, 1],
                    "acc_z_counts": code[:, 2]}, part)  # fmt: skip


def test_counts_refused_for_a_duty_cycle_part(sim, tmp_path):
    from accelnav.model.load import DEFAULT_MODEL

    duty = DEFAULT_MODEL.parent / "adxl202_duty.toml"
    with pytest.raises(UserError, match="duty-cycle part"):
        read_input({"t": sim.t, "acc_x_counts": sim.code[:, 0], "acc_y_counts": sim.code[:, 1]}, duty)


def test_axis_subset_narrows_the_model(part, sim, tmp_path):
    """A 3-axis part with z on gravity: --axis x --axis y keeps the model's x and y (fails today: refused
    as "2 axes ... for the model's 3")."""
    path = _csv(tmp_path / "rec.csv", sim, ["acc_x_counts", "acc_y_counts", "acc_z_counts"])
    run, model = read_input(path, part, axes=["x", "y"])
    assert [a.name for a in model.axes] == ["x", "y"]
    assert model.axes[1] == part.axes[1]  # its calibration kept
    np.testing.assert_array_equal(run["accel"], sim.accel[:, :2])
    with pytest.raises(UserError, match="for the model's 3"):  # columns that name no model axis: refused
        read_input({"t": sim.t, "acc_u_counts": sim.code[:, 0], "acc_v_counts": sim.code[:, 1]}, part)
