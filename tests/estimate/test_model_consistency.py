"""Issue 23 (a): NIS of the aids against the model, the fix-only baselines, and smooth --tune.

The recording: a simulated vehicle whose bias wanders 30x faster (sigma_eps) than the shipped model says,
with 1 Hz position fixes (sigma 0.5 m). Smoothed with the shipped model (30x too stiff), the fixes disagree
with it and the smoothed track is worse than the fixes alone; with the right model, or after --tune, it is
consistent and beats both baselines.
"""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.cli import main
from accelnav.data.runfile import load_run, save_run
from accelnav.estimate.consistency import aid_innovations, fix_to_fix_integration, interpolate_fixes, nis_check
from accelnav.estimate.kf import double_integrate, position_fix, run_filter
from accelnav.estimate.pipeline import BASELINES, fix_baselines, smooth_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design
from accelnav.model.edit import dump_model, with_noise
from accelnav.model.load import load_model

STIFF = 30.0
FIX_SIGMA = 0.5


@pytest.fixture(scope="module")
def vehicle():
    shipped = load_model(None)
    right = with_noise(shipped, sigma_eps=shipped.noise.sigma_eps * STIFF)
    run = simulate(right, "vehicle", 60.0, 4).to_arrays()
    rng = np.random.default_rng(1)
    step = int(round(shipped.rate_hz))  # 1 Hz
    fixes = [
        [
            position_fix(k, run["r"][k, j] + FIX_SIGMA * rng.standard_normal(), FIX_SIGMA)
            for k in range(0, len(run["t"]), step)
        ]
        for j in range(len(run["axis_names"]))
    ]
    return run, shipped, right, fixes


def _rms_vs_truth(run, est):
    return float(np.sqrt(np.mean((np.asarray(est) - run["r"].T) ** 2)))


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


def test_the_stiff_model_loses_to_the_baselines_and_smooth_says_so(vehicle, tmp_path, capsys):
    run, shipped, right, fixes = vehicle
    out = smooth_run(run, shipped, fixes=fixes)
    base = fix_baselines(out, shipped)
    assert set(base) == set(BASELINES)
    worst_base = max(_rms_vs_truth(run, b) for b in base.values())
    assert _rms_vs_truth(run, out["smooth_x"][:, :, 0]) > worst_base  # the failure the check must report
    path, fx_csv = _files(tmp_path, run, shipped, fixes)
    assert main(["smooth", str(path), "--fixes", str(fx_csv), "--out", str(tmp_path / "o.npz")]) == 0
    text = capsys.readouterr().out
    assert "fixes disagree with the model: mean NIS" in text and "too stiff" in text
    assert "the smoother misses the held-out fixes more than" in text
    assert "against the truth the smoother" in text
    for name in BASELINES:
        assert name in text


def test_right_model_is_quiet_and_tune_beats_both_baselines(vehicle, tmp_path, capsys):
    run, shipped, right, fixes = vehicle
    path, fx_csv = _files(tmp_path, run, shipped, fixes)
    model_path = tmp_path / "right.toml"
    model_path.write_text(dump_model(right))
    assert (
        main(
            ["smooth", str(path), "--model", str(model_path), "--fixes", str(fx_csv), "--out", str(tmp_path / "r.npz")]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "consistent with the model" in text and "try --tune" not in text

    assert main(["smooth", str(path), "--fixes", str(fx_csv), "--tune", "--out", str(tmp_path / "t.npz")]) == 0
    text = capsys.readouterr().out
    assert "budget 300 evaluations, 60 s" in text and "; used" in text
    assert "try --tune" not in text
    tuned, model = load_run(tmp_path / "t.npz")
    assert model.noise.sigma_eps > 10 * shipped.noise.sigma_eps  # the saved run carries the tuned model
    smoother = _rms_vs_truth(run, tuned["smooth_x"][:, :, 0])
    for name, r in fix_baselines(tuned, model).items():
        assert smoother < _rms_vs_truth(run, r), name


def test_tune_stops_at_its_time_budget(vehicle, tmp_path, capsys):
    run, shipped, _, fixes = vehicle
    path, fx_csv = _files(tmp_path, run, shipped, fixes)
    argv = [
        "smooth",
        str(path),
        "--fixes",
        str(fx_csv),
        "--tune",
        "--tune-seconds",
        "1e-6",
        "--out",
        str(tmp_path / "b.npz"),
    ]
    assert main(argv) == 0
    assert "stopped at its budget" in capsys.readouterr().out
    assert main(argv[:-2] + ["--tune-evaluations", "3", "--out", str(tmp_path / "c.npz")]) == 2
    assert "--tune-evaluations: got 3" in capsys.readouterr().err


def _files(tmp_path, run, model, fixes):
    path = tmp_path / "veh.npz"
    save_run(path, run, model)
    fx_csv = tmp_path / "fixes.csv"
    rows = ["time_s,axis,position_m,sigma_m"]
    for j, fx in enumerate(fixes):
        rows += [f"{float(run['t'][m.k])!r},{run['axis_names'][j]},{m.z!r},{float(np.sqrt(m.R))!r}" for m in fx]
    fx_csv.write_text("\n".join(rows) + "\n")
    return path, fx_csv


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
