"""``accelnav codegen MODEL.toml --out DIR [--report]``: write the generated C and its manifest."""

from __future__ import annotations

import argparse
from pathlib import Path

from accelnav.codegen.emit_c import emit, write
from accelnav.errors import UserError
from accelnav.model.load import load_model, name_problem


def register(sub) -> None:
    p = sub.add_parser(
        "codegen",
        help="generate the per-axis filter in C (fixed point or float32) and its manifest",
        description="Generate PREFIX.h, PREFIX.c and PREFIX.json for every axis of the model.",
    )
    p.add_argument("model", type=Path, help="model file (TOML)")
    p.add_argument("--out", type=Path, required=True, help="output directory (created if missing)")
    p.add_argument("--form", choices=("covariance", "gain_schedule"), help="override [filter] form of the model")
    p.add_argument("--float32", action="store_true", help="emit the float32 variant instead of fixed point")
    p.add_argument("--prefix", default="accelnav", help="file and symbol prefix (default: accelnav)")
    p.add_argument("--report", action="store_true", help="print ranges, formats, error bounds, flash and RAM")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.out.exists() and not args.out.is_dir():
        raise UserError(f"--out: {args.out} is a file; give a directory for the generated files")
    # the prefix names the files and every symbol: a C identifier (no path, no code), by the model's rule
    problem = name_problem("C prefix", args.prefix)
    if problem is not None:
        raise UserError(f"--prefix: got {ascii(args.prefix[:80])}; accepted: {problem}")
    model = load_model(args.model)
    arith = "float32" if args.float32 else "fixed"
    files = emit(model, form=args.form, arith=arith, prefix=args.prefix)
    for path in write(files, args.out):
        print(path)
    if args.report:
        from accelnav.codegen.report import report

        print(report(model, form=args.form, arith=arith, files=files, prefix=args.prefix))
    return 0
