"""The rest decision rewritten for speed (issue 31, its cost: its kinematic filter and each candidate's
statistics in C, a candidate's peak speed computed only when looked at) decides exactly as it did: on every
scenario of the rest benches (bench/speed/bench_rest_hypotheses.py, bench_rest_decision.py), with and without
their fixes, the same candidates are accepted with the same reasons and the same evidence in words, and the
statistics of each verdict agree to rounding. Every part the rewrite changed is kept as it was in
tests/support/rests_reference.py and swapped in here: the module as it was runs beside the new one on the same
record.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MODELS, edited_model
from support.cart_model import adxl335_model
from support.rests_reference import swapped

from accelnav.estimate import zupt
from accelnav.estimate.pipeline import fixes_per_axis
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.load import load_model

CASES = [  # scenario, model, seconds: the rest benches' cases
    ("highway_gnss", "moving start", 300.0),
    ("town_drive", "default", 400.0),
    ("stop_and_go", "default", 300.0),
    ("tilting_mount", "default", 300.0),
    ("hand_box", "adxl335", 120.0),
    ("walking", "foot_imu", 120.0),
    ("walking_still_start", "foot_imu", 60.0),
    ("jogging", "foot_imu", 120.0),
]


def _model(name: str):
    if name == "adxl335":
        return adxl335_model()
    if name == "moving start":  # as the hypotheses bench runs highway_gnss: the speed's prior widened
        return edited_model([("initial_sigma = [0.0, 0.0, 0.05, 0.05]", "initial_sigma = [0.0, 20.0, 0.05, 0.05]")])
    return load_model(None if name == "default" else MODELS / f"{name}.toml")


def _verdicts(arrays, model, fixes, params=None):
    cand = zupt.candidates(arrays["accel"], arrays["clipped"], model)
    params = params or zupt.ZuptParams()
    dec = zupt.decide_rests(arrays["accel"], arrays["clipped"], cand, model, params, fixes=fixes).decisions
    return [(d.start, d.stop, d.accepted, d.reason, d.evidence) for d in dec], np.array(
        [(d.still, d.level, d.v_before, d.sd_before, d.v_after, d.sd_after, d.chi2) for d in dec]
    )


@pytest.mark.parametrize("scenario,model_name,seconds", CASES)
def test_the_float_filter_decides_as_the_numpy_one(scenario, model_name, seconds):
    model = _model(model_name)
    arrays = simulate(model, scenario, seconds, 1).to_arrays()
    given = [None] + ([fixes_per_axis({**arrays, "fixes": arrays["sim_fixes"]})] if "sim_fixes" in arrays else [])
    for fixes in given:
        new, new_stats = _verdicts(arrays, model, fixes)
        with swapped():
            old, old_stats = _verdicts(arrays, model, fixes)
        assert new, f"{scenario}: no candidates: the comparison would hold nothing"
        what = "with fixes" if fixes else "without fixes"
        for o, n in zip(old, new, strict=True):
            assert n == o, f"{scenario} {what}: the old parts decided\n  {o}\nthe new ones\n  {n}"
        assert len(new) == len(old)
        # the statistics each verdict reports: the same sums in another order, equal to rounding
        np.testing.assert_allclose(new_stats, old_stats, rtol=1e-9, atol=1e-12, equal_nan=True, err_msg=scenario)


@pytest.mark.parametrize(
    "scenario,model_name,seconds", [("stop_and_go", "default", 300.0), ("tilting_mount", "default", 300.0)]
)
def test_few_marks_decide_as_many(scenario, model_name, seconds, monkeypatch):
    """A pass resumes at the last mark before the first new veto; marks kept sparse (so that a long drive's copies
    stay bounded) only replay more: the same verdicts, and never more marks than the cap."""
    from accelnav.estimate import rests

    model = _model(model_name)
    arrays = simulate(model, scenario, seconds, 1).to_arrays()
    dense, dense_stats = _verdicts(arrays, model, None)
    kept = []
    real = rests._Decider._resume

    def counting(self):
        kept.append(len(self._marks))
        return real(self)

    monkeypatch.setattr(rests, "MARKS", 3)
    monkeypatch.setattr(rests._Decider, "_resume", counting)
    sparse, sparse_stats = _verdicts(arrays, model, None)
    assert len(kept) > 1, f"{scenario}: one pass only: no resume was tried"
    assert max(kept) <= 3 + 1, f"{scenario}: {max(kept)} marks kept, the cap is 3"
    assert sparse == dense
    np.testing.assert_array_equal(sparse_stats, dense_stats)


@pytest.mark.parametrize(
    "scenario,model_name,seconds", [("tilting_mount", "default", 300.0), ("hand_box", "adxl335", 120.0)]
)
def test_a_resumed_pass_reads_the_proven_rests_before_its_mark(scenario, model_name, seconds):
    """A pass that resumes at a mark carries the stillness the rests before the mark proved (the kernel rebuilds it
    from the verdicts it keeps, not from a copy per mark). With a stillness bound of 1.5 R these records resume
    after rests proved still, and a stand's bound (twice their median) decides verdicts after the mark: a pass
    that lost them decides otherwise."""
    model = _model(model_name)
    arrays = simulate(model, scenario, seconds, 1).to_arrays()
    params = zupt.ZuptParams(still_k=1.5)
    new, new_stats = _verdicts(arrays, model, None, params)
    with swapped():
        old, old_stats = _verdicts(arrays, model, None, params)
    assert new == old
    np.testing.assert_allclose(new_stats, old_stats, rtol=1e-9, atol=1e-12, equal_nan=True)
