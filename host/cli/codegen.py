"""``accelnav codegen MODEL.toml --out DIR [--report] [--target PART]``: write the generated C and its manifests:
the filter and (fixed point) the frame code, every generated file the firmware build needs."""

from __future__ import annotations

import argparse
from pathlib import Path

from accelnav.codegen.generated import generate
from accelnav.codegen.package import write
from accelnav.errors import UserError
from accelnav.model.load import load_model, name_problem


def register(sub) -> None:
    p = sub.add_parser(
        "codegen",
        help="generate the per-axis filter in C (fixed point or float32) and its manifest",
        description="Generate PREFIX.h, PREFIX.c and PREFIX.json for every axis of the model and, for the fixed-point "
        "filter, the telemetry frame code acnframe.{h,c,json}: every generated file the firmware build needs.",
    )
    p.add_argument("model", type=Path, help="model file (TOML)")
    p.add_argument("--out", type=Path, help="output directory (created if missing)")
    p.add_argument(
        "--arduino",
        type=Path,
        metavar="DIR",
        help="write an Arduino library instead: DIR/accelnav_MODELNAME/ (the AccelNav class, library.properties "
        "and library.json, two example sketches); needs --maintainer and --url",
    )
    p.add_argument("--maintainer", metavar="'NAME <EMAIL>'", help="--arduino: who maintains the library")
    p.add_argument("--url", metavar="URL", help="--arduino: where a person reads about the library (http/https)")
    p.add_argument(
        "--board",
        metavar="BOARD",
        default="uno",
        help="--arduino: link the example sketches for BOARD (uno, the default; none: no link) and refuse a model "
        "whose sketch would not fit",
    )
    p.add_argument("--form", choices=("covariance", "gain_schedule"), help="override [filter] form of the model")
    p.add_argument("--float32", action="store_true", help="emit the float32 variant instead of fixed point")
    p.add_argument("--prefix", default="accelnav", help="file and symbol prefix (default: accelnav)")
    p.add_argument("--report", action="store_true", help="print ranges, formats, error bounds, flash and RAM")
    p.add_argument(
        "--target",
        metavar="PART",
        help="check the filter fits PART's flash and RAM (compiled with its compiler and the firmware's flags): "
        "atmega328p/uno, sifive_e/fe310, mps2_an385/cortex-m3, microbit/nrf51, stm32f103; a form that does not "
        "fit is refused, naming the form that does",
    )
    p.set_defaults(func=cmd_codegen)


def cmd_codegen(args: argparse.Namespace) -> int:
    if args.arduino is not None:
        return _codegen_arduino(args)
    if args.out is None:
        raise UserError("codegen: give --out DIR (the generated C) or --arduino DIR (an Arduino library)")
    if args.out.exists() and not args.out.is_dir():
        raise UserError(f"--out: {args.out} is a file; give a directory for the generated files")
    # the prefix names the files and every symbol: a C identifier (no path, no code), by the model's rule
    problem = name_problem("C prefix", args.prefix)
    if problem is not None:
        raise UserError(f"--prefix: got {ascii(args.prefix[:80])}; accepted: {problem}")
    part = None
    if args.target is not None:
        from accelnav.codegen import targets

        try:
            part = targets.part(args.target)  # an unknown part is refused before any work
        except targets.TargetError as e:
            raise UserError(str(e)) from None
    model = load_model(args.model)
    arith = "float32" if args.float32 else "fixed"
    files = generate(model, form=args.form, arith=arith, prefix=args.prefix)
    fit = None
    if part is not None:  # measured before anything is written: a filter that does not fit is not written
        try:
            fit = targets.fit(part, model, args.form or model.filter.form, arith, files, args.prefix)
        except targets.TargetError as e:
            raise UserError(str(e)) from None
        if fit.refusal():
            raise UserError(fit.refusal())
    for path in write(files, args.out):
        print(path)
    if args.report:
        from accelnav.codegen.report import report

        print(report(model, form=args.form, arith=arith, files=files, prefix=args.prefix))
    if fit is not None:
        print("\n".join(fit.lines()))
    return 0


def _codegen_arduino(args: argparse.Namespace) -> int:
    """The model's Arduino library in DIR/accelnav_MODELNAME/: each folder written by the generator's writer."""
    from accelnav.codegen.arduino import library, library_name, sketch_fit

    if args.out is not None or args.float32 or args.prefix != "accelnav":
        raise UserError("--arduino DIR: the library's folder and names are fixed; drop --out, --float32 and --prefix")
    if args.arduino.exists() and not args.arduino.is_dir():
        raise UserError(f"--arduino: {args.arduino} is a file; give a directory for the library")
    if args.maintainer is None or args.url is None:
        raise UserError("--arduino: give --maintainer 'NAME <EMAIL>' and --url URL (library.properties and "
                        "library.json name who maintains the library and where to read about it)")  # fmt: skip
    model = load_model(args.model)
    try:
        files = library(model, form=args.form, maintainer=args.maintainer, url=args.url)
        fit = [] if args.board == "none" else sketch_fit(files, library_name(model), args.board)
    except ValueError as e:
        raise UserError(str(e)) from None
    if fit and fit[1]:
        raise UserError(fit[1])  # measured before anything is written: a sketch that does not fit is not written
    root = args.arduino / library_name(model)
    folders: dict[str, dict[str, str]] = {}
    for path, text in files.items():
        folder, _, name = path.rpartition("/")
        folders.setdefault(folder, {})[name] = text
    for folder, group in sorted(folders.items()):
        for path in write(group, root / folder if folder else root):
            print(path)
    if fit:
        print("\n".join(fit[0]))
    print(f"Arduino library {root.name} in {root}: open examples/*/ in the IDE, or `make` there (arduino-mk)")
    return 0
