"""Every input of filter, smooth and tune, whatever its form, checked against the model.

One reader for the command and the library alike, so both make the same checks: the model's rate, its
axes, units, gaps (refused, or filled in and flagged with ``allow_gaps``), NaN, and samples at the
sensor's full scale (flagged as clipped). Notes on how a clock was read go to
:func:`accelnav.progress.note`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

import numpy as np

from accelnav.data.run import Run
from accelnav.data.runfile import load_run
from accelnav.errors import UserError
from accelnav.estimate.checks import check_run
from accelnav.fileio import check_input
from accelnav.model.load import Model, load_model, loads_model
from accelnav.progress import note

if TYPE_CHECKING:
    import pandas

Source = Union[str, "os.PathLike[str]", Mapping[str, Any], "pandas.DataFrame"]
# option -> the command's flag, which the messages name (the library's keywords map one to one)
FLAGS = {"axes": "axis", "time_column": "time_column", "rate_hz": "rate", "unit": "unit", "time_unit": "time_unit"}


def read_input(
    source: Source,
    model: Model | str | os.PathLike[str] | None = None,
    *,
    axes: list[str] | None = None,
    time_column: str | None = None,
    rate_hz: float | None = None,
    time_unit: str | None = None,
    unit: str | None = None,
    allow_gaps: bool = False,
) -> tuple[Run, Model]:
    """Read a run or recording and check it against the model; returns (run, model).

    ``source``: a path (an accelnav run file, a recorder log, a CSV or gzip CSV, an NPZ of t and
    accel), a mapping of named columns (numpy arrays, read as a CSV with that header: ``t`` or
    ``t_ms``, ``acc_x_g``, ...), or a pandas DataFrame of such columns. ``model``: a Model, a model
    file, or None for the model embedded in the input, else the embedded default. The keywords are
    the command's ``--axis``, ``--time-column``, ``--rate``, ``--time-unit``, ``--unit`` and
    ``--allow-gaps``. Anything refused raises :class:`accelnav.errors.UserError` (or ModelError) in
    one line.
    """
    opts = dict(axes=axes, time_column=time_column, rate_hz=rate_hz, time_unit=time_unit, unit=unit)
    override = model if isinstance(model, Model) or model is None else load_model(model)
    if not isinstance(source, (str, os.PathLike)):
        return _from_memory(source, override, opts, allow_gaps)
    from accelnav.data.imu import sniff
    from accelnav.link.logfile import is_log

    imu_log = sniff(source) is not None  # a phone or IMU log (a file, its zip, its folder): read_recording levels it
    path = Path(source) if imu_log else check_input(source)  # what it is, when not a readable file
    if not imu_log and is_log(path):
        from accelnav.data.logs import log_run_arrays

        arrays, model = log_run_arrays(path)
        if override is not None:  # a log's frames came from firmware built for its part: another kind is wrong
            _other_part(path, override, model)
        return _with_model(path, arrays, model, override, opts)
    if not imu_log and _is_run_file(path):
        arrays, model = load_run(path)
        return _with_model(path, arrays, model, override, opts)
    # a recording: CSV, gzip CSV, or an NPZ of t and accel
    from accelnav.data.recording import read_recording

    rec = read_recording(
        path, **opts, allow_gaps=allow_gaps, default_unit=_unit(override), model_axes=target_axes(override)
    )
    return _on_model(path, rec, override, chosen=bool(axes))


def target_axes(model: Model | None) -> list[str]:
    """The axis names a recording's columns are matched to by name: the model's, else the embedded default's."""
    return [a.name for a in (model if model is not None else load_model(None)).axes]


def _part(model: Model) -> str:
    kind = model.sensor.kind.replace("_", "-")
    return f"{'an' if kind[0] in 'aeiou' else 'a'} {kind} part"


def _unit(model: Model | None) -> str | None:
    """The unit a column that does not name one is in: a calibrated model's (its samples' unit), or raw ADC
    counts for an analog model (what its firmware samples)."""
    if model is not None and model.sensor.kind == "calibrated":
        return model.sensor.calibrated.unit
    if model is not None and model.sensor.kind == "analog":
        return "counts"
    return None


def _from_memory(source, override: Model | None, opts: dict, allow_gaps: bool) -> tuple[Run, Model]:
    """Columns in memory: a run's arrays (with ``accel`` and ``axis_names``), or named columns as a CSV has."""
    from accelnav.data.recording import from_columns

    if hasattr(source, "columns") and hasattr(source, "index"):  # a pandas DataFrame
        label = "<DataFrame>"
        columns = {str(c): _values(source[c]) for c in source.columns}
        index = source.index
        timed = _tz(index) is not None or index.dtype.kind in "Mm"
        name = index.name if index.name is not None else "time" if timed else None
        if name is not None and str(name) not in columns:  # time as the index (a DatetimeIndex, say)
            columns = {str(name): _values(index), **columns}
    elif isinstance(source, Mapping):
        label = "<arrays>"
        columns = {str(k): v for k, v in source.items()}
    else:
        raise UserError(
            f"read_input: got a {type(source).__name__}; accepted: a path, a mapping of arrays or a pandas DataFrame"
        )
    if "accel" in columns and "axis_names" in columns:  # a run's arrays (simulate, load_run)
        arrays = {k: np.asarray(v) for k, v in columns.items()}
        for key in ("t", "clipped"):
            if key not in arrays:
                raise UserError(f"{label}: a run's arrays need {key!r}; keys: {', '.join(sorted(arrays))}")
        if override is not None:
            model = override
        elif "model_toml" in arrays:
            model = loads_model(str(arrays["model_toml"]), source=f"{label}:model_toml")
        else:
            model = load_model(None)
        return _with_model(label, arrays, model, None, opts)
    rec = from_columns(
        label, columns, **opts, allow_gaps=allow_gaps, default_unit=_unit(override), model_axes=target_axes(override)
    )
    return _on_model(label, rec, override, chosen=bool(opts["axes"]))


def _tz(values):
    """The time zone of tz-aware pandas times (a Series' or an index's dtype has one), else None."""
    return getattr(values.dtype, "tz", None)


def _values(values) -> np.ndarray:
    """A pandas column or index as numpy; tz-aware times as their UTC datetime64 (numpy has no time zones)."""
    if _tz(values) is not None:
        if hasattr(values, "dt"):  # a Series: its times through .dt
            values = values.dt.tz_convert("UTC").dt.tz_localize(None)
        else:
            values = values.tz_convert("UTC").tz_localize(None)
    return values.to_numpy()


def _on_model(path, rec, model: Model | None, chosen: bool = False) -> tuple[Run, Model]:
    """A recording checked against the model and placed on its grid: rate, axes, NaN, gaps, full scale.

    ``chosen``: the columns were named with --axis; naming fewer than the model has, each by a model
    axis's name, narrows the model to those axes (a 3-axis part with one axis on gravity, say)."""
    from accelnav.data.recording import check_rate, check_rec_units, in_accel, on_grid

    for text in rec.notes:
        note(text)
    if model is None:
        model = load_model(None) if rec.model_toml is None else loads_model(rec.model_toml, source=f"{path}:model_toml")
    check_rate(rec, model.rate_hz, str(model.source))
    check_rec_units(rec, model.max_accel_m_s2, f"{model.source}")
    model, names = model_axes(path, model, list(rec.axis_names), list(rec.columns), chosen)
    said = len(rec.notes)
    rec = in_accel(rec, model)  # raw counts -> m/s^2 by the model's own read-out and calibration
    for text in rec.notes[said:]:
        note(text)
    bad = ~np.isfinite(rec.accel)
    if bad.any():
        k = int(np.argmax(bad.any(axis=1)))
        raise UserError(f"{path}: {rec.where(k)} is not a number (NaN/inf); a gap in the data is not accepted")
    # ranges.max_run_s bounds the fixed-point C's range proof, not these float64 tools: the bound here is the
    # memory that the filled-in input arrays (t, accel, clipped, twice while filling) take
    from accelnav.estimate.chunked import memory_available

    names = [a.name for a in model.axes]
    max_n = memory_available() // (2 * (8 + 9 * len(names)) + 1)
    limit = "the input arrays this machine's free memory holds number at most"
    t, accel, missing = on_grid(rec, rec.rate_hz, max_n, limit)  # its own clock: within 1 % of the model by now
    # at the sensor's declared full scale a sample is clipped (as a digital part saturates); missing ones too
    with np.errstate(invalid="ignore"):
        clipped = np.abs(accel) >= model.max_accel_m_s2 * (1 - 1e-9)
    clipped |= missing[:, None]
    if rec.clipped is not None and not missing.any():
        clipped |= rec.clipped
    if missing.any():
        note(f"{path}: {int(missing.sum())} missing samples filled in (predict only)")
    if len(rec.axis_names) and list(rec.columns) != names:  # say how the file's columns were taken
        note(f"{path}: columns {', '.join(rec.columns)} -> model axes {', '.join(names)}")
    arrays = {"t": t, "axis_names": np.array(names), "accel": accel, "clipped": clipped}
    return Run(arrays), model


def model_axes(src, model: Model, axis_names: list[str], columns: list[str], chosen: bool) -> tuple[Model, list[str]]:
    """(model, its axis names) for a recording's axes: narrowed to them when they were chosen (--axis)
    by the names of fewer model axes; a count that still differs is refused in one line. The whole and
    the streamed readers both decide here."""
    names = [a.name for a in model.axes]
    if chosen and len(axis_names) < len(names) and set(axis_names) <= set(names):
        model = narrowed(model, axis_names)
        note(f"{src}: model {model.name} narrowed to axes {', '.join(axis_names)}")
        names = list(axis_names)
    if len(axis_names) != len(names):
        raise UserError(
            f"{src}: {len(axis_names)} axes ({', '.join(columns)}) for the model's {len(names)} "
            f"({', '.join(names)}); choose the columns with --axis, one per model axis, in its order"
        )
    return model, names


def narrowed(model: Model, axes: list[str]) -> Model:
    """``model`` with only ``axes`` (model axis names, in that order), validated again by the loader."""
    import dataclasses

    from accelnav.model.edit import revalidate

    kept = tuple(model.axis(a) for a in axes)
    return revalidate(dataclasses.replace(model, axes=kept), source=f"{model.source} (axes {', '.join(axes)})")


def _is_run_file(path: Path) -> bool:
    """An NPZ (whatever its name) that is not a recording's NPZ of t and accel: an accelnav run file."""
    with open(path, "rb") as fh:
        zipped = fh.read(2) == b"PK"
    return (zipped or path.suffix.lower() == ".npz") and not _is_recording_npz(path)


def _is_recording_npz(path: Path) -> bool:
    """An NPZ of t and accel without the run file's format key (else it is read, and refused, as a run file)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
    except (OSError, zipfile.BadZipFile):
        return False
    return "accel.npy" in names and "format.npy" not in names


def _other_part(path, override: Model, recorded: Model) -> None:
    """A --model that does not fit the run because it is of another kind of part is refused naming that
    cause, not the rate or the axes it gets wrong (a run holds acceleration: a model of another kind with
    the same axes and rate is a legitimate override of the numbers; a log's is not, see read_input)."""
    if override.sensor.kind != recorded.sensor.kind:
        raise UserError(
            f"{override.source}: {_part(override)}, but {path} was recorded from {_part(recorded)} "
            f"({recorded.source}): give a model of that part"
        )


def _with_model(path, arrays, model: Model, override: Model | None, opts: dict) -> tuple[Run, Model]:
    """A run's arrays against its model (or the one given): the same axes, the model's rate, no gap."""
    from accelnav.data.recording import GAP_FACTOR

    for key, flag in FLAGS.items():
        if opts[key] not in (None, []):
            raise UserError(f"--{flag.replace('_', '-')}: only for CSV and NPZ recordings; {path} is a run file")
    if "accel" not in arrays:
        from accelnav.data.recording import no_input

        no_input(str(path), arrays)
    recorded = model
    if override is not None:
        if [a.name for a in override.axes] != [str(a) for a in arrays["axis_names"]]:
            _other_part(path, override, recorded)
            raise UserError(
                f"{override.source}: axes {[a.name for a in override.axes]} do not match the run's "
                f"{[str(a) for a in arrays['axis_names']]}"
            )
        model = override
    try:
        check_run(arrays, model, str(path))
    except UserError:
        if override is not None:
            _other_part(path, override, recorded)
        raise
    t = arrays["t"]
    if len(t) > 2:
        dt = np.diff(t)
        step = float(np.median(dt))
        if np.any(dt > GAP_FACTOR * step):
            k = int(np.argmax(dt > GAP_FACTOR * step))
            raise UserError(
                f"{path}: gap in time of {dt[k]:.6g} s after sample {k}; a run file is not filled in "
                "(--allow-gaps is for CSV and NPZ recordings: export the samples with --csv)"
            )
    return Run(arrays), model
