"""The planner computes and checks, the emitter formats (issue 22): codegen.plan returns every number the
C carries, and a model the C cannot carry is refused there, before any text is produced."""

from __future__ import annotations

import pytest

import accelnav.codegen.emit_c as emit_c
import accelnav.codegen.follow as follow
import accelnav.codegen.gains as gains
import accelnav.codegen.plan as plan_mod
import accelnav.codegen.ranges as ranges
from accelnav.codegen.ranges import RangeError
from accelnav.model.load import load_model


def _refuse(*args, **kwargs):
    raise AssertionError("planning work done while emitting")


@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
def test_emit_only_formats_the_plan(form, monkeypatch):
    """With the plan made first, emit gives the same files while every planning step (formats, the gain
    schedule, its return thresholds) refuses to run."""
    model = load_model()
    want = emit_c.emit(model, form=form)
    codes = plan_mod.plan(model, form)
    monkeypatch.setattr(emit_c, "plan", lambda m, f=None: codes)
    for mod, name in ((ranges, "plan_axis"), (plan_mod, "plan_axis"), (gains, "schedule_of"),
                      (plan_mod, "schedule_for"), (follow, "thresholds")):  # fmt: skip
        monkeypatch.setattr(mod, name, _refuse)
    assert emit_c.emit(model, form=form) == want


def test_a_range_refusal_comes_from_the_planner_before_any_text(monkeypatch):
    """A shift of the gain schedule's return after a skip that the C cannot take is refused as a RangeError
    (one line, the model and its key) by the planner: no axis' C is written first."""
    model = load_model()
    written = []
    monkeypatch.setattr(emit_c, "_axis_fixed", lambda c, prefix: written.append(c) or _refuse())

    def cannot(p, thr):
        raise ValueError("dK_r shift 70 - n out of range")

    monkeypatch.setattr(follow, "follow_plan", cannot)
    with pytest.raises(RangeError, match="filter.form: 'gain_schedule' after a skip: dK_r shift") as e:
        emit_c.emit(model, form="gain_schedule")
    assert "\n" not in str(e.value) and model.source in str(e.value)
    assert written == []


def test_the_plan_holds_the_quantised_constants():
    for c in plan_mod.plan(load_model(), "gain_schedule"):
        for name, (value, fmt, q) in c.consts.items():
            assert q == plan_mod.quantize(value, fmt), name
        assert c.sched is not None and c.follow is not None and c.merge is not None and c.eoff is not None
