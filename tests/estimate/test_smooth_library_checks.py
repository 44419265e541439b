"""What ``accelnav smooth`` used to compute in the CLI, called as the library: the consistency checks of a
smoothed run (pipeline.smooth_checks) and the tuning of its noise figures (tune.tune_run)."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.estimate.kf import position_fix
from accelnav.estimate.pipeline import smooth_checks, smooth_run
from accelnav.estimate.tune import FIGURES, tune_run
from accelnav.hil_sim.sim.sensor import simulate

FIX_SIGMA = 0.05


@pytest.fixture(scope="module")
def run(default_model):
    sim = simulate(default_model, "vehicle", 40.0, 3)
    arrays = sim.to_arrays()
    rng = np.random.default_rng(4)
    ks = range(0, len(sim.t), 500)  # a fix every 5 s
    fixes = [
        [position_fix(k, float(sim.r[k, j] + FIX_SIGMA * rng.standard_normal()), FIX_SIGMA) for k in ks]
        for j in range(len(sim.axis_names))
    ]
    return arrays, fixes


def test_checks_with_fixes_have_the_nis_and_the_held_out_comparison(run, default_model):
    arrays, fixes = run
    smoothed = smooth_run(arrays, default_model, fixes=fixes)
    c = smooth_checks(smoothed, default_model, arrays, fixes)
    assert [n.kind for n in c.nis] == ["fixes"] and c.nis[0].n == sum(map(len, fixes))
    assert c.holdout is not None and c.holdout.n == sum(len(f) // 2 for f in fixes)
    lines = c.lines()
    assert lines[0] == c.nis[0].line() and lines[1].startswith("held-out fixes (every other one left out")


def test_checks_without_aids_say_nothing(run, default_model):
    arrays, _ = run
    c = smooth_checks(smooth_run(arrays, default_model), default_model, arrays)
    assert c.nis == () and c.holdout is None and c.lines() == []


def test_tune_run_returns_the_rounded_model_of_its_result(run, default_model):
    arrays, fixes = run
    seen = []
    model, r = tune_run(default_model, arrays, fixes=fixes, max_evaluations=30, announce=lambda *a: seen.append(a))
    assert seen == [(len(arrays["t"]), len(default_model.axes), sum(map(len, fixes)))]
    assert set(r.figures) == set(FIGURES) and not r.converged  # 30 evaluations: stopped at the budget
    for f in FIGURES:  # as a model file holds them: 6 digits
        assert getattr(model.noise, f) == float(f"{r.chosen[f]:.6g}")


@pytest.mark.parametrize(("kw", "words"), [({"max_evaluations": 5}, "max_evaluations: got 5"),
                                           ({"max_seconds": 0.0}, "max_seconds: got 0")])  # fmt: skip
def test_tune_run_refuses_a_budget_it_cannot_search_in(run, default_model, kw, words):
    with pytest.raises(ValueError, match=f"^{words}"):
        tune_run(default_model, run[0], **kw)
