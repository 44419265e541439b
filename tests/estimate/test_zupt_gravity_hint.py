"""smooth --zupt auto on a 3-axis part with z on gravity: when no rest is accepted the summary says which
axis reads about 1 g (the detector's decisions are unchanged: the note only reads the data)."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.cli import main
from accelnav.estimate import zupt
from accelnav.model.edit import save_model
from accelnav.model.load import G0
from accelnav.model.new import new_model, preset

sensor = pytest.importorskip("accelnav.hil_sim.sim.sensor")


@pytest.fixture(scope="module")
def part():
    values = {k: v for k, v in preset("adxl335", 3.3).items() if k not in ("kind", "axes")}
    return new_model("adxl335_zupt", "analog", 100.0, ("x", "y", "z"), supply_v=3.3, adc_bits=12, **values).model


def _summary(tmp_path, capsys, part, scenario, gravity):
    run = sensor.simulate(part, scenario, 60.0, seed=1)
    accel = run.accel.copy()
    accel[:, 2] += G0 if gravity else 0.0
    model = tmp_path / "m.toml"
    save_model(model, part)
    path = tmp_path / "rec.csv"
    cols = ["t", "acc_x_m_s2", "acc_y_m_s2", "acc_z_m_s2"]
    np.savetxt(path, np.column_stack([run.t, accel]), delimiter=",", header=",".join(cols), comments="")
    out = tmp_path / "o.npz"
    assert main(["smooth", str(path), "--model", str(model), "--zupt", "auto", "--out", str(out)]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if s.startswith("zero-velocity detector")]
    assert len(line) == 1
    return line[0]


def test_no_rest_and_gravity_on_z_is_said(tmp_path, capsys, part):
    line = _summary(tmp_path, capsys, part, "sinusoid", gravity=True)
    assert " 0 accepted" in line and "axis z reads about 1 g (gravity)" in line and "--axis" in line


def test_no_hint_without_gravity_or_with_rests(tmp_path, capsys, part):
    assert "gravity" not in _summary(tmp_path, capsys, part, "sinusoid", gravity=False)
    assert "gravity" not in _summary(tmp_path, capsys, part, "stop_and_go", gravity=True)  # rests were found


def test_gravity_axes_reads_only_the_data(part):
    run = sensor.simulate(part, "stop_and_go", 30.0, seed=2)
    accel = run.accel.copy()
    assert zupt.gravity_axes(accel, run.clipped, part) == []
    accel[:, 2] -= G0  # upside down
    assert zupt.gravity_axes(accel, run.clipped, part) == ["z"]
