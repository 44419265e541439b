"""What accelnav smooth says about its rests and its model (issue 31, "checks that act"), on simulated runs: the
rests that disagree dropped and named before any advice, no "try --tune" after --tune, a run with nothing
anchoring it said. The numbers behind the lines: tests/estimate/test_advice_lines.py."""

from __future__ import annotations

import numpy as np
import pytest
from support.cli import run_cli
from support.vehicle_fixes import write_files

from accelnav.data.runfile import load_run
from accelnav.estimate import zupt
from accelnav.estimate.kf import position_fix
from accelnav.hil_sim.sim.sensor import simulate

MOVING = 0.5  # m/s


def _files(tmp_path, model, scenario, fix_every_s, fix_sigma):
    run = simulate(model, scenario, 60.0, 3).to_arrays()
    rng = np.random.default_rng(3)
    ks = range(0, len(run["t"]), int(round(fix_every_s * model.rate_hz)))
    fixes = [
        [position_fix(k, float(run["r"][k, j] + fix_sigma * rng.standard_normal()), fix_sigma) for k in ks]
        for j in range(len(run["axis_names"]))
    ]
    return write_files(tmp_path, run, model, fixes)


def test_rests_at_speed_are_dropped_and_named_before_the_noise_lines(tmp_path, capsys, default_model):
    """Every candidate accepted (--zupt-gate 0): the review drops the ones at speed against the fixes, named in
    the first line of the checks."""
    path, fx = _files(tmp_path, default_model, "cart_push", 5.0, 0.01)
    out = tmp_path / "o.npz"
    eager = ["--zupt", "auto", "--zupt-gate", "0", "--fixes", fx]
    status, text, err = run_cli(["smooth", path, *eager, "--out", out], capsys)
    assert status == 0, err
    lines = text.splitlines()
    (i,) = [k for k, x in enumerate(lines) if x.startswith("rests re-examined: ")]
    assert int(lines[i].split()[2]) > 0
    assert "disagree with the rest of the evidence, dropped: " in lines[i] and "(against the fixes: " in lines[i]
    assert all(not x.startswith(("fixes ", "rests disagree", "held-out")) for x in lines[:i])
    arrays, _ = load_run(out)
    speed = np.linalg.norm(load_run(path)[0]["u"], axis=1)  # the truth, in the input
    for a, b in zupt.intervals(arrays["zupt"].any(axis=1)):
        assert speed[a:b].max() < MOVING
    # with --tune the rests are re-examined before the figures are fitted to them, and said so in that order
    argv = ["smooth", path, *eager, "--tune", "--tune-evaluations", "10", "--out", out]
    status, tuned, err = run_cli(argv, capsys)
    assert status == 0, err
    order = [x.split(":")[0] for x in tuned.splitlines() if x.startswith(("rests re-examined", "tune:"))]
    assert order == ["rests re-examined", "tune", "tune"]
    arrays, _ = load_run(out)
    # the run file's candidates say which were finally used: the dropped ones are not
    used = arrays["zupt_candidates"][arrays["zupt_candidates"][:, 2] > 0]
    t = arrays["t"]
    for t0, t1, _ in used:
        assert speed[(t >= t0) & (t <= t1)].max() < MOVING


def test_no_try_tune_after_tune(tmp_path, capsys, default_model):
    path, fx = _files(tmp_path, default_model, "highway", 1.0, 1.0)
    argv = ["smooth", path, "--fixes", fx, "--out", tmp_path / "a.npz"]
    status, text, err = run_cli(argv, capsys)
    assert status == 0, err
    assert "fixes disagree with the model" in text and text.count("try --tune") == 3  # NIS, held out, truth
    status, text, err = run_cli([*argv[:-2], "--tune", "--tune-evaluations", "10", "--out", tmp_path / "b.npz"], capsys)
    assert status == 0, err
    assert "stopped at its budget: the best figures found, not a maximum" in text
    assert "fixes disagree with the tuned model" in text and "--tune" not in text.split("\ntune: ", 1)[1]


@pytest.mark.parametrize("fixes", [False, True])
def test_nothing_anchoring_the_run_is_said(tmp_path, capsys, default_model, fixes):
    path, fx = _files(tmp_path, default_model, "highway", 1.0, 1.0)
    argv = ["smooth", path, "--zupt", "auto", "--out", tmp_path / "h.npz"] + (["--fixes", fx] if fixes else [])
    status, text, err = run_cli(argv, capsys)
    assert status == 0, err
    said = [x for x in text.splitlines() if x.startswith("no rest applied and no fixes: nothing anchors")]
    assert len(said) == (0 if fixes else 1)


def test_tune_does_not_fit_the_rests_that_disagree(tmp_path, capsys, default_model, monkeypatch):
    """accelnav tune --zupt auto with an over-eager decision (every candidate accepted): the rests at speed are
    dropped (and named) before the figures are fitted, and only the rests kept are tuned to."""
    from dataclasses import replace

    from accelnav.estimate import engine

    eager = zupt.decide_rests
    monkeypatch.setattr(zupt, "decide_rests", lambda *a, **k: eager(*a[:4], replace(a[4], gate=0.0), *a[5:], **k))
    path, fx = _files(tmp_path, default_model, "cart_push", 5.0, 0.01)
    argv = ["tune", path, "--zupt", "auto", "--fixes", fx, "--max-evaluations", "10", "--out", tmp_path / "m.toml"]
    status, text, err = run_cli(argv, capsys)
    assert status == 0, err
    lines = text.splitlines()
    (i,) = [k for k, x in enumerate(lines) if x.startswith("rests re-examined: ")]
    (j,) = [k for k, x in enumerate(lines) if "zero-velocity updates per axis" in x]
    assert i < j and int(lines[i].split()[2]) > 0
    arrays, _ = load_run(path)
    p = zupt.resolved(default_model, zupt.ZuptParams())
    names = [str(a) for a in arrays["axis_names"]]
    from accelnav.estimate.fixes import read_fixes

    rest = engine.rest_stage(default_model, arrays, engine.Rests(p, detect=True),
                             fixes=read_fixes(fx, arrays["t"], names)).mask  # fmt: skip
    speed = np.linalg.norm(arrays["u"], axis=1)
    assert all(speed[a:b].max() < MOVING for a, b in zupt.intervals(rest))
    kept = int(rest.sum())
    assert f"zero-velocity updates per axis {kept}, {kept};" in lines[j]


def test_tune_says_which_figures_a_walk_does_not_identify(tmp_path, capsys):
    """A foot's jolts make the likelihood want R -> 0 and sigma_n in the hundreds (issue 31): R stops at the
    sensor's noise floor, and the line says R is not identified there, and that the budget ran out."""
    run = tmp_path / "w.npz"
    assert run_cli(["sim", "--scenario", "walking", "--duration", "20", "--seed", "1", "--out", run], capsys)[0] == 0
    argv = ["smooth", run, "--zupt", "auto", "--tune", "--tune-evaluations", "150", "--out", tmp_path / "o.npz"]
    status, text, err = run_cli(argv, capsys)
    assert status == 0, err
    (line,) = [x for x in text.splitlines() if x.startswith("tune: sigma_n")]
    assert "stopped at its budget: the best figures found, not a maximum" in line
    assert line.endswith(
        "; R not identified: at its lower bound (the sensor's rounding and datasheet noise floor, 0.00158)"
    )
