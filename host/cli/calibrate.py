"""``accelnav calibrate``: zero-g offset and sensitivity per axis from a recording of still poses.

The recording (CSV, NPZ or an accelnav run file, read by :mod:`accelnav.data.recording`) holds the part
turned through several still poses: the six-position test (each axis up and down; with the 2-axis ADXL250,
x up/down, y up/down and flat), or any set of at least four aligned poses, or, with a 3-axis part, any set
of at least six still poses in arbitrary orientations (the gravity-magnitude fit; ten or more also give the
angles between the axes). The method is chosen from the poses and named in the report. Its accelerations
must be the ones the model's current calibration gives (``--model``; else the model embedded in the
recording; else the embedded default): calibrate measures what that conversion gets wrong. The poses are found
automatically (:func:`accelnav.identify.calibrate.detect_poses`), the per-axis offset, sensitivity and
(where the poses allow) cross-axis terms are fitted with 95 % intervals, and the model is written with:

* each axis's ``zero_g`` and ``sensitivity`` (native units: V and V/g, or duty and duty/g) replaced by
  the calibrated ones;
* each calibrated axis's bias moved so that it is zero when the calibration was recorded (the offset
  measured then is now in zero_g): c2 = -c1 (1 - exp(-t/T)), t = ``--since-power-on`` (default: the
  warm-up had settled, c2 = -c1); c1 and T are kept.

Cross-axis terms are reported, not written: the model file has no key for them.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from accelnav.data.recording import read_recording
from accelnav.errors import UserError
from accelnav.identify.calibrate import GRAVITY, Calibration, CalibrationError, calibrate, detect_poses, native
from accelnav.model.design import input_conversion
from accelnav.model.edit import revalidate, save_model
from accelnav.model.load import DEFAULT_MODEL, G0, Model, load_model, loads_model
from accelnav.progress import Progress

MAX_SAMPLES = 10_000_000  # about 28 h at 100 Hz; the pose search holds a few copies of the samples


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="zero-g offset and sensitivity per axis from a recording of still poses (six-position test, or any "
        "orientations of a 3-axis part)",
        description="Find the still poses in a recording, fit each axis's zero-g offset, sensitivity and "
        "cross-axis terms with 95 %% intervals, and write them into a model file.",
    )
    p.add_argument("recording", type=Path, help="CSV (plain or gzip), NPZ or accelnav run file")
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        metavar="IN.toml",
        help="the model whose calibration converted the recording; default: the model embedded in the "
        f"recording, else the embedded {DEFAULT_MODEL.name}",
    )
    p.add_argument("--out", type=Path, required=True, metavar="OUT.toml", help="model file to write")
    p.add_argument("--unit", default=None, help="unit of the acceleration columns: g, mg or m/s^2")
    p.add_argument(
        "--rate",
        type=float,
        default=None,
        metavar="HZ",
        help="sample rate if there is no time column; with one, the nominal rate it is checked against "
        "(overriding stamps that do not fit it, said in a note)",
    )
    p.add_argument(
        "--time-unit",
        choices=("s", "ms", "us"),
        default=None,
        help="CSV/NPZ: unit of the time column when its name does not say it (t_ms does); default s",
    )
    p.add_argument("--time-column", default=None, metavar="NAME", help="time column; default: t, t_s, time, ...")
    p.add_argument("--min-pose", type=float, default=3.0, metavar="S", help="shortest still pose, s; default: 3")
    p.add_argument(
        "--since-power-on",
        type=float,
        default=None,
        metavar="S",
        help="time from power-on to the calibration (sets c2 = -c1 (1 - exp(-S/T))); default: warm-up settled",
    )
    p.add_argument("--no-cross", action="store_true", help="fit offset and sensitivity only")
    p.set_defaults(func=cmd_calibrate)


def _base_model(path: Path | None, model_toml: str | None, source: str) -> tuple[Model, str]:
    if path is not None:
        return load_model(path), str(path)
    if model_toml is not None:
        return loads_model(model_toml, source=f"{source}:model_toml"), f"the model embedded in {source}"
    return load_model(DEFAULT_MODEL), f"the embedded default {DEFAULT_MODEL.name}"


def steps_and_noise(model: Model) -> tuple[np.ndarray, float]:
    """Read-out step per model axis [m/s^2] and the analog noise sd in front of it [m/s^2]."""
    steps = []
    for i in range(len(model.axes)):
        conv = input_conversion(model, i)
        if model.sensor.kind == "analog":
            steps.append(conv.scale)
        else:
            steps.append(G0 / (model.sensor.duty_cycle.t2_counts * model.axes[i].sensitivity))
    s = model.sensor
    noise = s.noise_density_g_rthz * G0 * math.sqrt(math.pi / 2.0 * s.bandwidth_hz)
    return np.array(steps), noise


def cmd_calibrate(args: argparse.Namespace) -> int:
    if args.min_pose <= 0:
        raise UserError(f"--min-pose: got {args.min_pose:g}; accepted: seconds > 0")
    if args.since_power_on is not None and args.since_power_on < 0:
        raise UserError(f"--since-power-on: got {args.since_power_on:g}; accepted: seconds >= 0")
    rec = read_recording(
        args.recording,
        axes=None,
        unit=args.unit,
        rate_hz=args.rate,
        time_column=args.time_column,
        time_unit=args.time_unit,
    )
    for note in rec.notes:
        print(note)
    if rec.n > MAX_SAMPLES:
        raise UserError(f"{rec.source}: {rec.n} samples; accepted: at most {MAX_SAMPLES} (cut the recording)")
    model, label = _base_model(args.model, rec.model_toml, rec.source)
    names = tuple(a.name for a in model.axes)
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
    steps, noise = steps_and_noise(model)
    print(
        f"{rec.source}: {rec.n} samples at {rec.rate_hz:.6g} Hz ({rec.duration:.6g} s); model axes {', '.join(names)}"
    )
    try:
        with Progress("poses", total=2, unit="stages") as p:
            poses = detect_poses(acc, rec.rate_hz, steps=steps, noise_sd=noise, min_pose_s=args.min_pose)
            p.update(1)
            cal = calibrate(poses, names, cross=not args.no_cross)
            p.update(2)
    except CalibrationError as exc:
        raise UserError(f"{rec.source}: {exc}") from None
    print("\n".join(report(cal, names)))
    out_model = apply(model, cal, args.since_power_on)
    save_model(args.out, out_model, header=provenance(rec, cal, label))  # whole or not at all
    unit_z, unit_s = ("V", "V/g") if model.sensor.kind == "analog" else ("duty", "duty/g")
    print(f"model written to {args.out} (from {label}):")
    for old, new in zip(model.axes, out_model.axes, strict=True):
        print(
            f"  axis {new.name}: zero_g {old.zero_g:.6g} -> {new.zero_g:.6g} {unit_z}, sensitivity "
            f"{old.sensitivity:.6g} -> {new.sensitivity:.6g} {unit_s}; bias c2 {old.c2:.4g} -> {new.c2:.4g} m/s^2 "
            "(zero at the calibration: its offset is now in zero_g)"
        )
    return 0


def apply(model: Model, cal: Calibration, since_power_on: float | None) -> Model:
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
    except Exception as exc:  # a calibration far outside the part's read-out span
        raise UserError(f"the calibrated model is not valid: {exc}") from None


def _ci(ci) -> str:
    return f"[{ci[0]:.6g}, {ci[1]:.6g}]"


def report(cal: Calibration, names: tuple[str, ...]) -> list[str]:
    out = [f"{len(cal.poses)} still poses:"]
    for k, p in enumerate(cal.poses):
        lv = ", ".join(f"{n} {int(v):+d}" for n, v in zip(names, p.level, strict=True))
        rd = ", ".join(f"{m / G0:+.5f}" for m in p.mean)
        lv = "" if cal.method == GRAVITY else f"  levels ({lv}) g"
        out.append(f"  {k + 1}: {p.t0:7.1f} .. {p.t1:7.1f} s{lv}  reads ({rd}) g")
    out.append(f"method: {cal.method}")
    for a in cal.axes:
        out.append(f"axis {a.name}:")
        out.append(
            f"  zero-g offset {a.offset:+.6g} m/s^2 ({a.offset / G0 * 1e3:+.4g} mg)  se {a.se['offset']:.3g}  "
            f"95 % {_ci(a.ci95['offset'])}"
        )
        out.append(f"  sensitivity x{a.scale:.6f} of the model's  se {a.se['scale']:.3g}  95 % {_ci(a.ci95['scale'])}")
        for k, v in a.cross.items():
            out.append(
                f"  cross-axis to {k}: {v:+.5f} (a {k} of 1 g reads {v * 1e3:+.3g} mg on {a.name})  se "
                f"{a.se[k]:.3g}  95 % {_ci(a.ci95[k])}  (reported, not written: the model has no cross-axis key)"
            )
        for m in a.not_identified:
            out.append(f"  not identifiable: {m}")
        scaled = " (intervals widened by chi2/dof, Student t)" if a.scaled else ""
        out.append(
            f"  fit: {a.dof} degrees of freedom, chi2 {a.chi2:.3g}, "
            f"residual rms {a.residual_rms / G0 * 1e3:.3g} mg{scaled}"
            + (" (of |gravity|, shared by the axes)" if cal.method == GRAVITY else "")
        )
    for pc in cal.pairs:
        out.append(
            f"axes {pc.name}: cosine of the angle between them {pc.value:+.5f} "
            f"({math.degrees(math.asin(pc.value)):+.3f} deg from square)  se {pc.se:.3g}  95 % {_ci(pc.ci95)}  "
            "(reported, not written)"
        )
    return out


def provenance(rec, cal: Calibration, label: str) -> str:
    lines = [
        "accelnav model written by accelnav calibrate",
        f"recording: {Path(rec.source).name}, {rec.n} samples at {rec.rate_hz:.6g} Hz, {len(cal.poses)} still poses",
        f"base: {label}",
        f"method: {cal.method}",
    ]
    for a in cal.axes:
        cross = "; ".join(f"cross to {k} {v:+.4g} +- {a.se[k]:.2g} (not written)" for k, v in a.cross.items())
        lines.append(
            f"axis {a.name}: offset {a.offset:+.5g} +- {a.se['offset']:.2g} m/s^2, sensitivity x{a.scale:.6f} +- "
            f"{a.se['scale']:.2g}" + (f"; {cross}" if cross else "")
        )
        for m in a.not_identified:
            lines.append(f"  not identifiable: {m}")
    for pc in cal.pairs:
        lines.append(f"axes {pc.name}: cos(angle) {pc.value:+.4g} +- {pc.se:.2g} (not written)")
    return "\n".join(lines)
