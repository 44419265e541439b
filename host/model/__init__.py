"""The model file and the numbers derived from it: what the estimators and the generator both stand on.

Nothing here imports the generator (``accelnav.codegen``) or the estimators, so the float64 oracle and
the fixed-point C are derived from one source without depending on each other.
"""

from .design import AnalogConversion, AxisDesign, DutyConversion, axis_design, input_conversion
from .edit import save_model
from .load import DEFAULT_MODEL, G0, Axis, Model, ModelError, load_model, loads_model

__all__ = [
    "DEFAULT_MODEL",
    "G0",
    "AnalogConversion",
    "Axis",
    "AxisDesign",
    "DutyConversion",
    "Model",
    "ModelError",
    "axis_design",
    "input_conversion",
    "load_model",
    "loads_model",
    "save_model",
]
