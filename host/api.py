"""The library's face: the functions ``import accelnav`` offers, each a thin, checked call into its stage.

Runs go in and come out as :class:`accelnav.data.run.Run` (a dict of the run file's arrays with
``to_dataframe``, ``to_npz`` and ``to_csv``); every refusal is an :class:`accelnav.errors.UserError` or a
:class:`accelnav.model.ModelError` with a one-line message, as the command prints it.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from accelnav.data.run import Run, as_run, pandas_or_error
from accelnav.errors import UserError
from accelnav.model.load import Model

if TYPE_CHECKING:
    from accelnav.estimate.pipeline import PositionErrors
    from accelnav.estimate.tune import TuneResult
    from accelnav.estimate.zupt import ZuptParams

PathLike = str | os.PathLike[str]


class Table(list):
    """Rows of dataclasses (one per axis or method) that also convert to a DataFrame."""

    def to_dataframe(self):
        pd = pandas_or_error()
        return pd.DataFrame([asdict(r) for r in self])


def load_run(path: PathLike) -> tuple[Run, Model]:
    """Read an accelnav run file (``.npz``); returns (run, the model embedded in it)."""
    from accelnav.data.runfile import load_run as _load

    arrays, model = _load(path)
    return Run(arrays), model


def save_run(path: PathLike, run: Mapping[str, np.ndarray], model: Model) -> None:
    """Write ``run`` and the model's text as an accelnav run file, whole or not at all."""
    from accelnav.data.runfile import save_run as _save

    _save(path, run, model)


def filter_run(run: Mapping[str, np.ndarray], model: Model) -> Run:
    """The float64 reference filter over every axis: adds ``filt_x`` (n_axes, N, 4) = [r, u, a, eps] and
    the covariances. Refuses a run whose rate or axes are not the model's."""
    from accelnav.estimate.pipeline import filter_run as _filter

    return Run(_filter(dict(run), model))


def smooth_run(
    run: Mapping[str, np.ndarray],
    model: Model,
    *,
    fixes: PathLike | Sequence[Sequence[Any]] | None = None,
    rest: np.ndarray | PathLike | None = None,
    zupt_params: ZuptParams | None = None,
) -> Run:
    """Filter and RTS-smooth every axis (compiled): adds ``filt_*``, ``smooth_x``, ``smooth_P``, ``zupt``.

    ``fixes``: position fixes, a CSV file (time_s, position_m, sigma_m[, axis]) or per-axis lists of
    measurements. ``rest``: an (N,) or (N, n_axes) mask of samples at rest (:func:`detect_rests`), or a
    file of rest intervals or a mask, as ``accelnav smooth --zupt FILE`` takes. Refuses a run whose
    rate or axes are not the model's.
    """
    from accelnav.estimate import zupt
    from accelnav.estimate.pipeline import smooth_run as _smooth

    arrays = dict(run)
    _check(arrays, model, "smooth_run")
    fixes = _fixes(fixes, arrays)
    rest_sigma = None
    if isinstance(rest, (str, os.PathLike)):
        rest, rest_sigma = zupt.read_zupt_file(rest, arrays["t"], [str(a) for a in arrays["axis_names"]])
    params = zupt_params
    if rest is not None:
        try:
            params = zupt.resolved(model, zupt.ZuptParams() if params is None else params)
        except ValueError as exc:
            raise UserError(f"zupt_params: {exc}") from None
    return Run(_smooth(arrays, model, fixes=fixes, rest=rest, zupt_params=params, rest_sigma=rest_sigma))


def detect_rests(
    run: Mapping[str, np.ndarray],
    model: Model,
    params: ZuptParams | None = None,
    fixes: PathLike | Sequence[Sequence[Any]] | None = None,
    *,
    candidates: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) bool: the samples of the rests ``accelnav smooth --zupt auto`` applies: those the zero-velocity
    decision accepts, judged against ``fixes`` too when given (as :func:`smooth_run` takes them; a rest where
    the fixes imply speed is refused), less those its review then finds refuted by a full smoother with the
    fixes or the other rests. :func:`decide_rests` gives each candidate's decision and its evidence.
    ``candidates``: an (N,) bool mask of rests found elsewhere (``accelnav.level``'s gyroscope-aided
    ``LevelResult.rests``) decided on instead of the accelerometer-only detector's."""
    from accelnav.estimate import engine, zupt

    arrays = dict(run)
    _check(arrays, model, "detect_rests")
    rests = engine.Rests(zupt.ZuptParams() if params is None else params, detect=True, candidates=candidates)
    return engine.rest_stage(model, arrays, rests, fixes=_fixes(fixes, arrays)).mask


def decide_rests(
    run: Mapping[str, np.ndarray],
    model: Model,
    params: ZuptParams | None = None,
    fixes: PathLike | Sequence[Sequence[Any]] | None = None,
    *,
    candidates: np.ndarray | None = None,
):
    """The detector's candidates and the decision on each (accelnav.estimate.zupt.Rests: ``decisions``, each with
    its reason and evidence in words, and ``mask``, the accepted ones: :func:`detect_rests` less the rests its
    review drops). ``candidates``: as :func:`detect_rests` takes them."""
    from accelnav.estimate import engine, zupt

    arrays = dict(run)
    _check(arrays, model, "decide_rests")
    try:
        params = zupt.resolved(model, zupt.ZuptParams() if params is None else params)
    except ValueError as exc:
        raise UserError(f"params: {exc}") from None
    given = engine.candidate_mask(candidates, len(arrays["accel"]))
    return zupt.decide_rests(arrays["accel"], arrays["clipped"], given, model, params, _fixes(fixes, arrays))


def position_errors(run: Mapping[str, np.ndarray], model: Model) -> Table:
    """With a simulated truth (``r``): rms and final position error per axis of each estimate in the run."""
    from accelnav.estimate.pipeline import position_errors as _errors

    rows: list[PositionErrors] = _errors(dict(run), model)
    return Table(rows)


def tune(
    run: Mapping[str, np.ndarray],
    model: Model,
    *,
    fixes: PathLike | Sequence[Sequence[Any]] | None = None,
    rest: np.ndarray | None = None,
    figures: Sequence[str] = ("sigma_n", "sigma_eps", "R"),
    max_evaluations: int | None = None,
) -> tuple[Model, TuneResult]:
    """Maximum-likelihood noise figures of this run (``accelnav tune``); returns (model with the chosen
    figures, the result with estimates, intervals and the likelihood-ratio verdict)."""
    from accelnav.estimate import zupt
    from accelnav.estimate.tune import MAX_EVALUATIONS, tune_run

    arrays = dict(run)
    _check(arrays, model, "tune")
    params = zupt.resolved(model, zupt.ZuptParams()) if rest is not None else None
    try:
        return tune_run(
            model,
            arrays,
            fixes=_fixes(fixes, arrays),
            rest=rest,
            params=params,
            figures=figures,
            max_evaluations=MAX_EVALUATIONS if max_evaluations is None else max_evaluations,
            intervals=True,
        )
    except ValueError as exc:
        raise UserError(f"tune: {exc}") from None


def generate(model: Model) -> dict[str, str]:
    """The C the firmware needs, as text: ``accelnav.{h,c,json}`` (the filter) and ``acnframe.{h,c,json}``."""
    from accelnav.codegen.generated import generated_files

    return dict(generated_files(model))


def simulate(model: Model, scenario: str = "vehicle", duration_s: float = 60.0, seed: int = 1) -> Run:
    """A simulated run of ``model``'s sensor: truth (r, u, a, eps), raw input and its conversion (accel)."""
    from accelnav.hil_sim.sim.sensor import simulate as _simulate

    try:
        sim = _simulate(model, scenario, duration_s, seed)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    return Run(sim.to_arrays())


def run_sil(model: Model, run: Mapping[str, np.ndarray]) -> Run:
    """Feed a simulated run's raw input to the firmware built from ``model``, in-process (cffi); returns the
    decoded telemetry as a run (``fw_x``: the firmware's fixed-point states) with the simulated truth."""
    from accelnav.data.logs import decoded_run
    from accelnav.hil_sim.targets import hil
    from accelnav.hil_sim.targets.firmware import manifest

    sim = _sim_run(model, run)
    man = manifest(model.source)
    return Run(decoded_run(model, sim, hil.run_sil(model, hil.stimulus(man, sim)), man))


def run_pil(
    model: Model, run: Mapping[str, np.ndarray], *, board: str = "mps2_an385", log: PathLike | None = None
) -> Run:
    """As :func:`run_sil`, on an emulated board (QEMU); the telemetry log goes to ``log`` (else a temporary
    folder). Needs qemu-system-arm and arm-none-eabi-gcc."""
    from accelnav.data.logs import decoded_run
    from accelnav.hil_sim.targets import hil
    from accelnav.hil_sim.targets.firmware import FirmwareError, manifest
    from accelnav.hil_sim.targets.qemu import QemuError

    sim = _sim_run(model, run)
    man = manifest(model.source)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(log) if log is not None else Path(tmp) / "pil.acnlog"
        try:
            res = hil.run_pil(model, hil.stimulus(man, sim), len(sim.t), path, board=board)
        except (QemuError, FirmwareError) as exc:
            raise UserError(str(exc).splitlines()[0]) from None
    return Run(decoded_run(model, sim, res.telemetry, man))


def _sim_run(model: Model, run: Mapping[str, np.ndarray]):
    """The SimRun behind simulate()'s arrays (truth and raw input, checked against ``model``)."""
    from accelnav.hil_sim.sim.sensor import SimRun

    try:
        return SimRun.from_arrays(model, dict(run))
    except ValueError as exc:
        raise UserError(f"run_sil/run_pil: not a run of simulate() on this model: {exc}") from None


def _check(arrays: dict, model: Model, where: str) -> None:
    from accelnav.estimate.checks import check_run

    check_run(arrays, model, where)


def _fixes(fixes, arrays: dict):
    if fixes is None or not isinstance(fixes, (str, os.PathLike)):
        return fixes
    from accelnav.estimate.fixes import read_fixes

    return read_fixes(fixes, arrays["t"], [str(a) for a in arrays["axis_names"]])


__all__ = [
    "Table",
    "as_run",
    "decide_rests",
    "detect_rests",
    "filter_run",
    "generate",
    "load_run",
    "position_errors",
    "run_pil",
    "run_sil",
    "save_run",
    "simulate",
    "smooth_run",
    "tune",
]
