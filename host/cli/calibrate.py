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
import math
from pathlib import Path

from accelnav.cli.args import clock_args, reader_options
from accelnav.identify.calibrate import GRAVITY, Calibration
from accelnav.identify.calibration import calibrate_recording
from accelnav.model.edit import save_model
from accelnav.model.load import DEFAULT_MODEL, G0


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="zero-g offset and sensitivity per axis from a recording of still poses (six-position test, or any "
        "orientations of a 3-axis part)",
        description="Find the still poses in a recording, fit each axis's zero-g offset, sensitivity and "
        "cross-axis terms with 95 % intervals, and write them into a model file.",
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
    p.add_argument(
        "--unit",
        default=None,
        help="unit of the acceleration columns: g, mg, m/s^2 or counts (raw read-out codes, converted by --model)",
    )
    clock_args(p)
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


def cmd_calibrate(args: argparse.Namespace) -> int:
    run = calibrate_recording(
        args.recording,
        args.model,
        **reader_options(args),
        min_pose_s=args.min_pose,
        since_power_on=args.since_power_on,
        cross=not args.no_cross,
    )
    rec, cal, model, out_model, label = run.recording, run.calibration, run.base, run.model, run.base_label
    names = tuple(a.name for a in model.axes)
    print("\n".join(report(cal, names)))
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


def _fmt_ci(ci) -> str:
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
            f"95 % {_fmt_ci(a.ci95['offset'])}"
        )
        out.append(
            f"  sensitivity x{a.scale:.6f} of the model's  se {a.se['scale']:.3g}  95 % {_fmt_ci(a.ci95['scale'])}"
        )
        for k, v in a.cross.items():
            out.append(
                f"  cross-axis to {k}: {v:+.5f} (a {k} of 1 g reads {v * 1e3:+.3g} mg on {a.name})  se "
                f"{a.se[k]:.3g}  95 % {_fmt_ci(a.ci95[k])}  (reported, not written: the model has no cross-axis key)"
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
            f"({math.degrees(math.asin(pc.value)):+.3f} deg from square)  se {pc.se:.3g}  95 % {_fmt_ci(pc.ci95)}  "
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
