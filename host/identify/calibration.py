"""``calibrate`` as the library runs it: a recording of still poses in, the model with calibrated axes out.

The chain of ``accelnav calibrate`` (see that command's notes): read and check the recording, find the
poses, fit offsets and sensitivities (:mod:`accelnav.identify.calibrate`), and write them into the model.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from accelnav.data.recording import Recording, check_rec_units, in_accel
from accelnav.errors import UserError
from accelnav.identify.calibrate import Calibration, CalibrationError, calibrate, detect_poses, native
from accelnav.model.design import steps_and_noise
from accelnav.model.edit import revalidate
from accelnav.model.load import DEFAULT_MODEL, Model, ModelError, load_model, loads_model
from accelnav.progress import Progress, note

MAX_SAMPLES = 10_000_000  # about 28 h at 100 Hz; the pose search holds a few copies of the samples


@dataclass(frozen=True, eq=False)
class CalibrationRun:
    """What :func:`calibrate_recording` found and the model it made."""

    model: Model  # the base model with each axis's zero_g, sensitivity and c2 replaced
    base: Model
    base_label: str
    recording: Recording
    calibration: Calibration

    def to_dataframe(self):
        """One row per axis: offset and scale with their standard errors, old and new zero_g and sensitivity."""
        from accelnav.data.run import pandas_or_error

        pd = pandas_or_error()
        rows = []
        for old, new in zip(self.base.axes, self.model.axes, strict=True):
            c = next(a for a in self.calibration.axes if a.name == new.name)
            rows.append(
                {
                    "axis": new.name,
                    "offset": c.offset,
                    "scale": c.scale,
                    "zero_g_before": old.zero_g,
                    "zero_g": new.zero_g,
                    "sensitivity_before": old.sensitivity,
                    "sensitivity": new.sensitivity,
                }
            )
        return pd.DataFrame(rows).set_index("axis")


def base_model(path: Path | None, model_toml: str | None, source: str) -> tuple[Model, str]:
    if path is not None:
        return load_model(path), str(path)
    if model_toml is not None:
        return loads_model(model_toml, source=f"{source}:model_toml"), f"the model embedded in {source}"
    return load_model(DEFAULT_MODEL), f"the embedded default {DEFAULT_MODEL.name}"


def apply(model: Model, cal: Calibration, since_power_on: float | None) -> Model:
    """``model`` with each axis's calibration replaced and its bias zero at the time of the calibration."""
    axes = []
    for ax in model.axes:
        c = next(a for a in cal.axes if a.name == ax.name)
        zero, sens = native(ax, c.offset, c.scale)
        settled = 1.0 if since_power_on is None else -math.expm1(-since_power_on / ax.T)
        axes.append(
            dataclasses.replace(ax, zero_g=float(f"{zero:.9g}"), sensitivity=float(f"{sens:.9g}"), c2=-ax.c1 * settled)
        )
    try:
        return revalidate(dataclasses.replace(model, axes=tuple(axes)))
    except (ModelError, ValueError) as exc:  # a calibration far outside the part's read-out span
        raise UserError(f"the calibrated model is not valid: {exc}") from None


def calibrate_recording(
    source: str | Path,
    model: Model | str | Path | None = None,
    *,
    unit: str | None = None,
    rate_hz: float | None = None,
    time_column: str | None = None,
    time_unit: str | None = None,
    min_pose_s: float = 3.0,
    since_power_on: float | None = None,
    cross: bool = True,
) -> CalibrationRun:
    """Offsets and sensitivities from a recording of still poses, written into ``model`` (else the model
    embedded in the recording, else the embedded default). Refusals raise UserError in one line."""
    if min_pose_s <= 0:
        raise UserError(f"--min-pose: got {min_pose_s:g}; accepted: seconds > 0")
    if since_power_on is not None and since_power_on < 0:
        raise UserError(f"--since-power-on: got {since_power_on:g}; accepted: seconds >= 0")
    from accelnav.identify.characterise import as_model_axes, read_stationary

    if model is not None and not isinstance(model, Model):
        model = load_model(Path(model))
    rec = read_stationary(source, unit=unit, rate_hz=rate_hz, time_column=time_column, time_unit=time_unit, model=model)
    if rec.n > MAX_SAMPLES:
        raise UserError(f"{rec.source}: {rec.n} samples; accepted: at most {MAX_SAMPLES} (cut the recording)")
    if isinstance(model, Model):
        base, label = model, str(model.source)
    else:
        base, label = base_model(None, rec.model_toml, rec.source)
    rec = as_model_axes(rec, base)
    check_rec_units(rec, base.max_accel_m_s2 if model is not None else None, label)
    if "counts" in rec.units:  # the model's own conversion (its current zero-g and sensitivity), as the firmware's;
        rec = in_accel(rec, base)  # without --model the default's, as filter and smooth read counts, said in a note
        note(rec.notes[-1])
    names = tuple(a.name for a in base.axes)
    missing = [n for n in names if n not in rec.axis_names]
    if missing:
        raise UserError(
            f"{rec.source}: the model's axes {', '.join(names)} must all be in the recording; missing "
            f"{', '.join(missing)} (the recording has {', '.join(rec.axis_names)})"
        )
    acc = np.column_stack([rec.axis(n) for n in names])
    bad = ~np.isfinite(acc)
    if bad.any():
        k = int(np.argmax(bad.any(axis=1)))
        raise UserError(f"{rec.source}: samples that are not numbers, the first at sample {k} (t = {rec.t[k]:.6g} s)")
    steps, noise = steps_and_noise(base)
    note(f"{rec.source}: {rec.n} samples at {rec.rate_hz:.6g} Hz ({rec.duration:.6g} s); model axes {', '.join(names)}")
    try:
        with Progress("poses", total=2, unit="stages") as p:
            poses = detect_poses(acc, rec.rate_hz, steps=steps, noise_sd=noise, min_pose_s=min_pose_s)
            p.update(1)
            cal = calibrate(poses, names, cross=cross)
            p.update(2)
    except CalibrationError as exc:
        raise UserError(f"{rec.source}: {exc}") from None
    return CalibrationRun(apply(base, cal, since_power_on), base, label, rec, cal)
