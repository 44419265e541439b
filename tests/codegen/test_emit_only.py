"""The emitter only formats: every number and every check is the planner's (codegen.plan), issue 22.

A calibrated sensor (data already in g) has no raw input for the generated C to read: both
arithmetics refuse it in one line naming the key, the float32 one included (it crashed with a bare
AttributeError on the duty-cycle branch).
"""

from __future__ import annotations

import sys
from types import ModuleType

import pytest
from conftest import MODELS

import accelnav.codegen.emit_c as emit_c
import accelnav.codegen.plan as plan_mod
from accelnav.codegen.emit_c import emit
from accelnav.model.load import ModelError, load_model


@pytest.mark.parametrize("arith", ["fixed", "float32"])
@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
def test_calibrated_model_is_refused_in_one_line(form, arith):
    model = load_model(MODELS / "foot_imu.toml")
    with pytest.raises(ModelError) as e:
        emit(model, form=form, arith=arith)
    msg = str(e.value)
    assert "\n" not in msg and "sensor.kind" in msg and "foot_imu.toml" in msg and "'calibrated'" in msg


def _shipped_codegen_models():
    """Every shipped model the generator accepts (a calibrated one is refused above)."""
    out = []
    for path in sorted(MODELS.glob("*.toml")):
        model = load_model(path)
        if model.sensor.kind != "calibrated":
            out.append(model)
    return out


def _no_numbers_here(*args, **kwargs):
    raise AssertionError("the emitter computed a number the plan should hold")


# what works out a number or decides a shift: qformat's helpers wherever they are imported, and the
# planner's own steps (their results are in the plan handed to emit)
QFORMAT_HELPERS = ("quantize", "dequantize", "guard_bits", "acc_bound", "const_format", "fit", "bits_for")
PLANNER_STEPS = (
    "cov_fracs",
    "cov_sums",
    "fine_view",
    "follow_plan",
    "check_follow",
    "thresholds",
    "layout",
    "plan_axis",
)


@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
def test_emit_formats_every_shipped_model_with_quantize_refusing(form, monkeypatch):
    """With the plan made first, every shipped model emits the same files while quantize, every qformat
    helper and every planning step raise in every codegen module (emit_c's namespace included): the
    quantised constants, the sums' shifts and guard bits, the follow step's shifts and the checks are all
    in the plan. Before, emit_c folded constants with quantize mid-emission and ran checks of its own."""
    models = _shipped_codegen_models()
    assert len(models) >= 2
    want = {m.source: emit(m, form=form) for m in models}
    codes = {m.source: plan_mod.plan(m, form) for m in models}
    monkeypatch.setattr(emit_c, "plan", lambda m, f=None: codes[m.source])
    for mod in [m for n, m in sys.modules.items() if n.startswith("accelnav.codegen") and type(m) is ModuleType]:
        for name in QFORMAT_HELPERS + PLANNER_STEPS:
            monkeypatch.setattr(mod, name, _no_numbers_here, raising=False)
    for m in models:
        assert emit_c.emit(m, form=form) == want[m.source], m.source
