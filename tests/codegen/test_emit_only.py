"""The emitter only formats: every number and every check is the planner's (codegen.plan), issue 22.

A calibrated sensor (data already in g) has no raw input for the generated C to read: both
arithmetics refuse it in one line naming the key, the float32 one included (it crashed with a bare
AttributeError on the duty-cycle branch).
"""

from __future__ import annotations

import pytest
from conftest import MODELS

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
