"""The generated C beside the float64 reference: builds and plans cached per model, the stated-bound check,
and a schedule with its skip-following cut out (a C the check must catch). Shared by the codegen lockstep
tests and the SIL/PIL matrix."""

from __future__ import annotations

import numpy as np

from accelnav.codegen.bounds import twin_bound
from accelnav.codegen.emit_c import _schedule_for, emit
from accelnav.codegen.ranges import plan_axis
from accelnav.hil_sim.targets.harness import build

SIGMA_FRACTION = 1e-3  # of the reference's own sigma, after the first second

_BUILT: dict = {}  # (model hash, form) -> (files, cffi module): each C built once per session
_PLAN: dict = {}


def built(model, form, workdir):
    key = (model.sha256, form)
    if key not in _BUILT:
        files = emit(model, form=form)
        _BUILT[key] = (files, build(files, workdir))
    return _BUILT[key]


def plan(model, axis, form):
    key = (model.sha256, axis, form)
    if key not in _PLAN:
        p = plan_axis(model, axis, form)
        _PLAN[key] = (p, _schedule_for(p) if form == "gain_schedule" else None)
    return _PLAN[key]


def check_against_bound(p, sched, code, z, valid, x_ref, x_c, what):
    """Every state within the stated bound at every step (codegen.bounds.twin_bound: the exact effect
    of the quantized constants plus a rigorous bound on the roundings of this run)."""
    bound, _ = twin_bound(p, code, z, valid, x_ref, sched)
    ratio = np.abs(x_c - x_ref) / bound
    worst = np.unravel_index(np.argmax(ratio), ratio.shape)
    assert ratio.max() <= 1.0, f"{what}: state {worst[1]} at sample {worst[0]} at {ratio.max():.3g} of the stated bound"
    return ratio


def blind_schedule(files: dict) -> dict:
    """The gain-schedule C with its skip-following cut out: it never leaves the schedule (the form as it
    was before codegen.follow)."""
    c = files["accelnav.c"]
    entry = "s->k |= ACCELNAV_X_FOLLOWING;"
    assert c.count(entry) >= 1, "the entry into the deviation"
    return {**files, "accelnav.c": c.replace(entry, "s->k |= 0u;")}
