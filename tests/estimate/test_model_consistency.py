"""Issue 23 (a): NIS of the aids against the model, the fix-only baselines, and smooth --tune.

The recording: a simulated vehicle whose bias wanders 30x faster (sigma_eps) than the shipped model says,
with 1 Hz position fixes (sigma 0.5 m). Smoothed with the shipped model (30x too stiff), the fixes disagree
with it and the smoothed track is worse than the fixes alone; with the right model, or after --tune, it is
consistent and beats both baselines.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.vehicle_fixes import STIFF, rms_vs_truth, vehicle_case

from accelnav.estimate.consistency import aid_innovations, fix_to_fix_integration, interpolate_fixes, nis_check
from accelnav.estimate.kf import double_integrate, position_fix, run_filter
from accelnav.estimate.pipeline import BASELINES, fix_baselines, smooth_checks, smooth_run
from accelnav.estimate.tune import tune_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design
from accelnav.model.edit import with_noise


@pytest.fixture(scope="module")
def vehicle():
    return vehicle_case()


@pytest.fixture(scope="module")
def tuned(vehicle):
    """smooth --tune's search through the library: the shipped model tuned on the run with its fixes."""
    run, shipped, _, fixes = vehicle
    return tune_run(shipped, run, fixes=fixes, max_evaluations=300)


def test_nis_fires_on_a_model_30x_too_stiff_and_is_quiet_on_the_right_one(vehicle):
    run, shipped, right, fixes = vehicle
    stiff = nis_check("fixes", smooth_run(run, shipped, fixes=fixes)["fix_nis"])
    good = nis_check("fixes", smooth_run(run, right, fixes=fixes)["fix_nis"])
    assert stiff.n == good.n == sum(map(len, fixes))
    assert stiff.verdict == "stiff" and "too stiff: try --tune" in stiff.line()
    assert good.verdict == "" and good.low <= good.mean <= good.high


def test_nis_replay_equals_the_reference_filter(vehicle):
    """y and S of each fix from the compiled forward pass = the float64 reference's, fix by fix."""
    run, shipped, _, fixes = vehicle
    n = 1500
    d = axis_design(shipped, 0)
    z, valid = run["accel"][:n, 0], ~run["clipped"][:n, 0]
    fx = [m for m in fixes[0] if m.k < n]
    out = smooth_run(
        {k: run[k][:n] if k != "axis_names" else run[k] for k in ("t", "axis_names", "accel", "clipped")},
        shipped,
        fixes=[fx, []],
    )
    y, S = aid_innovations(d, z, valid, out["filt_x_prior"][0], out["filt_P_prior"][0], fx)
    for i, m in enumerate(fx):
        ref = run_filter(d, z[: m.k + 1], valid=valid[: m.k + 1], extras=fx[:i])  # up to m's acceleration update
        y_ref = m.z - ref.x_post[m.k, 0]
        S_ref = ref.P_post[m.k, 0, 0] + m.R
        assert abs(y[i] - y_ref) <= 1e-9 * np.sqrt(S_ref) and abs(S[i] / S_ref - 1) <= 1e-9
    np.testing.assert_allclose(out["fix_nis"], y * y / S, rtol=1e-12)


def test_fix_to_fix_integration_lands_on_every_fix_and_is_exact_without_noise(default_model):
    d = axis_design(default_model, 0)
    n = 1001
    t = np.arange(n) * d.Ts
    a = np.sin(t) + 0.3 * np.cos(3 * t)
    r = double_integrate(d, a)[:, 0] + 2.0 + 0.7 * t  # some start position and speed
    m = d.eps_mean
    eps = m + (float(d.x0[3]) - m) * d.phi ** np.arange(n)  # the bias the model expects
    fixes = [position_fix(k, r[k], 0.1) for k in range(50, n, 100)]
    f2f = fix_to_fix_integration(d, t, a + eps, np.ones(n, bool), fixes)
    np.testing.assert_allclose(f2f, r, atol=1e-9)
    interp = interpolate_fixes(t, fixes)
    np.testing.assert_allclose(interp[[f.k for f in fixes]], [f.z for f in fixes], atol=1e-12)


def test_the_stiff_model_loses_to_the_baselines(vehicle):
    run, shipped, right, fixes = vehicle
    out = smooth_run(run, shipped, fixes=fixes)
    base = fix_baselines(out, shipped)
    assert set(base) == set(BASELINES)
    worst_base = max(rms_vs_truth(run, b) for b in base.values())
    assert rms_vs_truth(run, out["smooth_x"][:, :, 0]) > worst_base  # the failure the check must report


def test_right_model_is_quiet_and_tune_beats_both_baselines(vehicle, tuned):
    run, shipped, right, fixes = vehicle
    tuned, result = tuned
    assert result.adopted  # smooth --tune says "used"
    checks = smooth_checks(smooth_run(run, right, fixes=fixes), right, run, fixes)
    assert "consistent with the model" in checks.nis[0].line()
    assert not any("try --tune" in line for line in checks.lines())
    assert tuned.noise.sigma_eps > 10 * shipped.noise.sigma_eps
    out = smooth_run(run, tuned, fixes=fixes)
    assert not any("try --tune" in line for line in smooth_checks(out, tuned, run, fixes).lines())
    smoother = rms_vs_truth(run, out["smooth_x"][:, :, 0])
    for name, r in fix_baselines(out, tuned).items():
        assert smoother < rms_vs_truth(run, r), name


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_rest_nis_fires_on_a_model_30x_too_stiff_and_is_quiet_on_the_right_one(default_model, seed):
    """Stop-and-go with its true rests: the first update of each rest tests the velocity the model let grow."""
    run = simulate(default_model, "stop_and_go", 120.0, seed).to_arrays()
    rest = np.abs(run["u"][:, 0]) < 1e-9
    m = default_model.noise
    stiff = with_noise(default_model, sigma_n=m.sigma_n / STIFF, sigma_eps=m.sigma_eps / STIFF)
    checks = {}
    for name, model in (("right", default_model), ("stiff", stiff)):
        z = smooth_run(run, model, rest=rest)["zupt_nis"]
        first = z[:, 3] > 0
        assert 0 < first.sum() < len(z)  # one per rest and axis, of thousands of updates
        checks[name] = nis_check("rests", z[first, 2])
    assert checks["right"].verdict == "" and checks["stiff"].verdict == "stiff"
    assert checks["stiff"].line().startswith("rests disagree with the model: mean NIS")
