"""Sensors whose bias settles slowly (T of many minutes, as real parts show: the ADIS16405 fit
gave T = 2493 s) must be generated and stay in lockstep like the default's T = 300 s.

A longer T makes the bias more persistent, and the position gain K_r = (P_ra + P_re)/S larger
(past 1 for T = 1000 s at 100 Hz), so this checks that nothing in the format choice quietly
assumes a small K_r.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.codegen_lockstep import SIGMA_FRACTION, built, check_against_bound, plan

from accelnav.estimate.kf import run_filter
from accelnav.hil_sim.sim import sensor
from accelnav.hil_sim.targets.harness import AxisRunner
from accelnav.model.design import axis_design
from accelnav.model.load import load_model, loads_model


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("codegen_long_T")


def long_T_model(T: float):
    text = load_model().text.replace("T = 300.0", f"T = {T:.1f}")
    return loads_model(text, source=f"adxl250_default@T={T:g}s")


@pytest.mark.parametrize("T", [1000.0, 2500.0])
@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
@pytest.mark.parametrize("scenario", ["vehicle", "shock"])
def test_long_bias_time_constant_lockstep(T, form, scenario, workdir):
    model = long_T_model(T)
    files, mod = built(model, form, workdir)
    p, sched = plan(model, 0, form)
    assert p.gains.kmax[0] > 0.25  # the case this file is about
    run = sensor.simulate(model, scenario, 30.0, seed=12)
    d = axis_design(model, 0)
    valid = ~run.clipped[:, 0]
    ref = run_filter(d, run.accel[:, 0], valid=valid)
    sig = np.sqrt(np.einsum("kii->ki", ref.P_post))
    res = AxisRunner(mod, files["accelnav.json"], 0).run(code=run.code[:, 0])
    assert res["overflow"] == 0
    x_ref = ref.x_post  # the float64 Kalman filter with the same skips (both forms follow them)
    check_against_bound(p, sched, run.code[:, 0], run.accel[:, 0], valid, x_ref, res["x"], f"T={T:g}")
    err = np.abs(res["x"] - x_ref)[100:] / sig[100:]
    assert err.max() <= SIGMA_FRACTION, f"max error {err.max():.3g} sigma"
