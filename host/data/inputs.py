"""Every input of filter, smooth and tune, whatever its form, checked against the model.

Moved from the CLI so that the library makes the same checks (rate, axes, units, gaps,
clipping, NaN) as the command.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from accelnav.data.runfile import load_run
from accelnav.errors import UserError
from accelnav.fileio import check_input, check_output
from accelnav.model.load import Model, load_model, loads_model


def _load(args) -> tuple[dict[str, np.ndarray], Model]:
    """The input of filter and smooth, whatever its form, checked against the model (see INPUT_HELP)."""
    from accelnav.data.recording import check_rate, on_grid, read_recording
    from accelnav.link.logfile import is_log

    path = check_input(args.run)  # what it is, when not a readable file (a FIFO is refused before a read)
    for flag in ("out", "csv"):  # an output that cannot be written is refused before the work
        if getattr(args, flag, None) is not None:
            check_output(getattr(args, flag), f"--{flag}")
    override = load_model(args.model) if args.model is not None else None
    if is_log(path):
        from accelnav.data.logs import log_run_arrays

        arrays, model = log_run_arrays(path)
        return _with_model(path, arrays, model, override, args)
    with open(path, "rb") as fh:
        zipped = fh.read(2) == b"PK"  # an NPZ, whatever its name
    if (zipped or path.suffix.lower() == ".npz") and not _is_recording_npz(path):
        arrays, model = load_run(path)
        return _with_model(path, arrays, model, override, args)
    # a recording: CSV, gzip CSV, or an NPZ of t and accel
    model = override
    unit = args.unit
    if unit is None and model is not None and model.sensor.kind == "calibrated":
        unit = model.sensor.calibrated.unit
    rec = read_recording(
        path,
        axes=args.axis,
        unit=unit,
        rate_hz=args.rate,
        time_column=args.time_column,
        allow_gaps=args.allow_gaps,
        time_unit=args.time_unit,
    )
    for note in rec.notes:
        print(note)
    if model is None:
        model = load_model(None) if rec.model_toml is None else loads_model(rec.model_toml, source=f"{path}:model_toml")
    check_rate(rec, model.rate_hz, str(model.source))
    names = [a.name for a in model.axes]
    if len(rec.axis_names) != len(names):
        raise UserError(
            f"{path}: {len(rec.axis_names)} axes ({', '.join(rec.columns)}) for the model's {len(names)} "
            f"({', '.join(names)}); choose the columns with --axis, one per model axis, in its order"
        )
    bad = ~np.isfinite(rec.accel)
    if bad.any():
        k = int(np.argmax(bad.any(axis=1)))
        raise UserError(f"{path}: {rec.where(k)} is not a number (NaN/inf); a gap in the data is not accepted")
    max_n = int(np.ceil(model.ranges.max_run_s * model.rate_hz))
    t, accel, missing = on_grid(rec, rec.rate_hz, max_n)  # its own clock: within 1 % of the model by now
    # at the sensor's declared full scale a sample is clipped (as a digital part saturates); missing ones too
    with np.errstate(invalid="ignore"):
        clipped = np.abs(accel) >= model.max_accel_m_s2 * (1 - 1e-9)
    clipped |= missing[:, None]
    if rec.clipped is not None and not missing.any():
        clipped |= rec.clipped
    if missing.any():
        print(f"{path}: {int(missing.sum())} missing samples filled in (predict only)")
    if len(rec.axis_names) and list(rec.axis_names) != names:
        print(f"{path}: columns {', '.join(rec.columns)} -> model axes {', '.join(names)}")
    arrays = {"t": t, "axis_names": np.array(names), "accel": accel, "clipped": clipped}
    return arrays, model


def _is_recording_npz(path: Path) -> bool:
    """An NPZ of t and accel without the run file's format key (else it is read, and refused, as a run file)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
    except (OSError, zipfile.BadZipFile):
        return False
    return "accel.npy" in names and "format.npy" not in names


def _with_model(path, arrays, model: Model, override: Model | None, args) -> tuple[dict[str, np.ndarray], Model]:
    from accelnav.data.recording import GAP_FACTOR

    for flag in ("axis", "time_column", "rate", "unit", "time_unit"):
        if getattr(args, flag) not in (None, []):
            raise UserError(f"--{flag.replace('_', '-')}: only for CSV and NPZ recordings; {path} is a run file")
    if override is not None:
        if [a.name for a in override.axes] != [str(a) for a in arrays["axis_names"]]:
            raise UserError(
                f"{args.model}: axes {[a.name for a in override.axes]} do not match the run's "
                f"{[str(a) for a in arrays['axis_names']]}"
            )
        model = override
    t = arrays["t"]
    if len(t) > 2:
        dt = np.diff(t)
        step = float(np.median(dt))
        if abs(step * model.rate_hz - 1) > 0.01:
            raise UserError(
                f"{path}: the run is sampled at {1 / step:.6g} Hz but the model {model.source} has "
                f"sampling.rate_hz = {model.rate_hz:g} Hz"
            )
        if np.any(dt > GAP_FACTOR * step):
            k = int(np.argmax(dt > GAP_FACTOR * step))
            raise UserError(
                f"{path}: gap in time of {dt[k]:.6g} s after sample {k}; a run file is not filled in "
                "(--allow-gaps is for CSV and NPZ recordings: export the samples with --csv)"
            )
    return arrays, model
