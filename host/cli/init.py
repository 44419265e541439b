"""``accelnav init``: describe a new part and write its model file (accelnav.model.new)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from accelnav.errors import UserError

# flag dest -> (model key, prompt); asked for only when stdin is a terminal and the value is still missing
FIELDS = {
    "range_g": ("range_g", "full scale, +-g"),
    "noise_density": ("noise_density_g_rthz", "noise density, g/sqrt(Hz)"),
    "bandwidth": ("bandwidth_hz", "output filter -3 dB, Hz"),
    "supply": ("supply_v", "supply, V"),
    "adc_bits": ("adc_bits", "ADC bits"),
    "adc_ref": ("adc_ref_v", "ADC reference, V (the supply: ratiometric)"),
    "sensitivity": ("sensitivity_v_per_g", "sensitivity, V/g"),
    "zero_g": ("zero_g_v", "zero-g output, V"),
    "timer_clock": ("timer_clock_hz", "timer clock, Hz"),
    "t2": ("t2_period_s", "duty-cycle period T2, s"),
    "zero_g_duty": ("zero_g_duty", "duty at 0 g"),
    "duty_per_g": ("duty_per_g", "duty per g"),
    "lsb_per_g": ("lsb_per_g", "counts per g"),
}
NEEDED = {
    "analog": ("range_g", "noise_density", "bandwidth", "supply", "adc_bits", "sensitivity"),
    "duty_cycle": ("range_g", "noise_density", "bandwidth", "timer_clock", "t2", "duty_per_g"),
    "digital": ("range_g", "noise_density", "bandwidth", "lsb_per_g"),
    "calibrated": ("range_g", "noise_density", "bandwidth"),
}


def register(sub) -> None:
    p = sub.add_parser(
        "init",
        help="describe a new part (analog, duty-cycle, digital, calibrated) and write its model file",
        description="Write a complete, validated model file for a new part from its datasheet values: flags, a "
        "--part preset, or (when stdin is a terminal) questions for what is missing. Noise from the datasheet; "
        "the bias and calibration are placeholders that fit-bias and calibrate then measure.",
    )
    p.add_argument("--out", type=Path, required=True, metavar="OUT.toml", help="model file to write")
    p.add_argument("--force", action="store_true", help="replace an existing model file")
    p.add_argument("--part", default=None, help="a preset's datasheet values (adxl335, adxl250, adxl202)")
    p.add_argument("--kind", choices=("analog", "duty_cycle", "digital", "calibrated"), default=None)
    p.add_argument("--name", default=None, help="model name; default: from --out")
    p.add_argument("--axes", default=None, metavar="X,Y,Z", help="axis names, comma separated; default x,y")
    p.add_argument("--rate", type=float, default=None, metavar="HZ", help="sample rate, Hz")
    p.add_argument("--unit", choices=("g", "m/s^2"), default=None, help="calibrated: unit of the samples")
    for dest, (key, text) in FIELDS.items():
        kind = int if dest == "adc_bits" else float
        p.add_argument("--" + dest.replace("_", "-"), dest=dest, type=kind, default=None, help=f"{text} ({key})")
    p.set_defaults(func=cmd_init)


def _init_ask(text: str, kind=float):
    answer = input(f"{text}: ").strip()
    try:
        return kind(answer)
    except ValueError:
        raise UserError(f"{text}: got {answer!r}; expected a number") from None


def cmd_init(args: argparse.Namespace) -> int:
    from accelnav.fileio import output_target
    from accelnav.model.edit import save_model
    from accelnav.model.load import model_name_from
    from accelnav.model.new import new_model, part_values, preset

    out = output_target(args.out)
    if out.kind == "file" and out.path.exists() and not args.force:
        raise UserError(f"--out: {args.out} exists; give --force to replace it")
    if args.axes is not None and not all(a.strip() for a in args.axes.split(",")):
        raise UserError(f"--axes: got {args.axes!r}; accepted: axis names, comma separated (x,y,z)")
    # flags and answers fill one dict of model keys; the part's preset is applied to it once, after both
    # (a ratiometric sensitivity scaled by the supply however it was given: one path, one model)
    known = preset(args.part) if args.part else {}
    given = {key: getattr(args, dest) for dest, (key, _) in FIELDS.items() if getattr(args, dest) is not None}
    kind = args.kind or known.get("kind")
    asking = sys.stdin.isatty()
    if kind is None:
        if not asking:
            raise UserError("init: give --kind (analog, duty_cycle, digital, calibrated) or --part")
        kind = input("kind (analog, duty_cycle, digital, calibrated): ").strip()
        if kind not in NEEDED:
            raise UserError(f"init: kind {kind!r}; accepted: {', '.join(NEEDED)}")
    rate = args.rate
    have = {**known, **given}
    missing = [d for d in NEEDED[kind] if have.get(FIELDS[d][0]) is None] + (["rate"] if rate is None else [])
    if missing and not asking:
        raise UserError(f"init: {kind} part: give {', '.join('--' + m.replace('_', '-') for m in missing)}")
    for dest in missing:
        if dest == "rate":
            rate = _init_ask("sample rate, Hz")
        else:
            given[FIELDS[dest][0]] = _init_ask(FIELDS[dest][1], int if dest == "adc_bits" else float)
    values = part_values(args.part, given)
    axes = values.pop("axes", ("x", "y"))
    if args.axes is not None:
        axes = tuple(a.strip() for a in args.axes.split(","))
    if args.unit:
        values["unit"] = args.unit
    values.pop("kind", None)
    name = args.name or model_name_from(args.out.stem)
    new = new_model(name, kind, rate, axes, **values)
    model = save_model(args.out, new.model, header=new.header)  # read back through the loader before writing
    print(f"wrote {args.out}: {model.sensor.part or kind}, axes {', '.join(a.name for a in model.axes)}, "
          f"{model.rate_hz:g} Hz, R = {model.noise.R:.4g} (m/s^2)^2")  # fmt: skip
    print("next:")
    for step in new.next_steps:
        print(f"  {step}")
    return 0
