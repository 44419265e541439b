"""accelnav: short-duration position from a cheap accelerometer.

From Python, the names below are all a session needs (imported on first use, so ``import accelnav``
stays quick)::

    import accelnav
    run, model = accelnav.read_input("walk.csv", accelnav.load_model("my_sensor.toml"))
    run = accelnav.smooth_run(run, model, rest=accelnav.detect_rests(run, model), fixes="fixes.csv")
    frame = run.to_dataframe()

* models: ``Model``, ``ModelError``, ``load_model``, ``save_model``
* runs: ``read_input`` (a path, numpy arrays or a pandas DataFrame, checked as the command checks
  them), ``load_run``, ``save_run``; a ``Run`` converts with ``to_dataframe``, ``to_npz``, ``to_csv``
* estimation: ``filter_run``, ``smooth_run``, ``detect_rests``, ``position_errors``
* identification: ``characterise`` (bias fit and noise), ``calibrate``, ``tune``
* C and targets: ``generate`` (file name -> C text), ``simulate``, ``run_sil``, ``run_pil``
* refusals: ``UserError`` and ``ModelError``, each with a one-line message
* files to try it on: ``example_path("walk.csv")`` (a shipped recording), ``example_path("foot_imu.toml")``

The packages behind them, lowest first: ``model``, ``native`` -> ``estimate``, ``codegen``,
``hil_sim.sim`` -> ``link`` -> ``data`` -> ``identify``, ``hil_sim.targets`` -> ``plots`` -> ``cli``
(the ``accelnav`` command). Nothing imports upward and nothing imports the CLI (tests/package/test_layers.py).
"""

from __future__ import annotations

import importlib

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing (2 ms, more than the rest)

# public name -> (module, name in it)
_FACE = {
    "Model": ("accelnav.model.load", "Model"),
    "ModelError": ("accelnav.model.load", "ModelError"),
    "load_model": ("accelnav.model.load", "load_model"),
    "save_model": ("accelnav.model.edit", "save_model"),
    "UserError": ("accelnav.errors", "UserError"),
    "Run": ("accelnav.data.run", "Run"),
    "read_input": ("accelnav.data.inputs", "read_input"),
    "load_run": ("accelnav.api", "load_run"),
    "save_run": ("accelnav.api", "save_run"),
    "filter_run": ("accelnav.api", "filter_run"),
    "smooth_run": ("accelnav.api", "smooth_run"),
    "detect_rests": ("accelnav.api", "detect_rests"),
    "position_errors": ("accelnav.api", "position_errors"),
    "characterise": ("accelnav.identify.characterise", "characterise"),
    "calibrate": ("accelnav.identify.calibration", "calibrate_recording"),
    "tune": ("accelnav.api", "tune"),
    "generate": ("accelnav.api", "generate"),
    "simulate": ("accelnav.api", "simulate"),
    "run_sil": ("accelnav.api", "run_sil"),
    "run_pil": ("accelnav.api", "run_pil"),
    "example_path": ("accelnav.resources", "example_path"),
}

__all__ = [
    "Model",
    "ModelError",
    "Run",
    "UserError",
    "calibrate",
    "characterise",
    "detect_rests",
    "example_path",
    "filter_run",
    "generate",
    "load_model",
    "load_run",
    "position_errors",
    "read_input",
    "run_pil",
    "run_sil",
    "save_model",
    "save_run",
    "simulate",
    "smooth_run",
    "tune",
]


def _version() -> str:
    """The installed distribution's version (pyproject.toml is its one source); read on first use, since
    importlib.metadata alone costs more than the rest of ``import accelnav``."""
    from importlib import metadata

    try:
        return metadata.version("accelnav")
    except metadata.PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"


def __getattr__(name: str):
    if name == "__version__":
        globals()[name] = value = _version()
        return value
    if name in _FACE:
        module, attr = _FACE[name]
        value = getattr(importlib.import_module(module), attr)
        globals()[name] = value  # once: later lookups do not come back here
        return value
    raise AttributeError(f"module 'accelnav' has no attribute {name!r}")


def __dir__() -> list[str]:
    return [*__all__, "__version__"]


if TYPE_CHECKING:  # what type checkers and IDEs see; at run time the names above load on first use
    from accelnav.api import (
        detect_rests,
        filter_run,
        generate,
        load_run,
        position_errors,
        run_pil,
        run_sil,
        save_run,
        simulate,
        smooth_run,
        tune,
    )
    from accelnav.data.inputs import read_input
    from accelnav.data.run import Run
    from accelnav.errors import UserError
    from accelnav.identify.calibration import calibrate_recording as calibrate
    from accelnav.identify.characterise import characterise
    from accelnav.model.edit import save_model
    from accelnav.model.load import Model, ModelError, load_model
