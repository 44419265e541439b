"""``accelnav tune``: sigma_n, sigma_eps and R from a motion recording by maximum likelihood of the innovations.

Reads a run file (``accelnav sim``, ``accelnav log export``), takes its rests (``--zupt auto`` or a CSV of
intervals) and position fixes (``--fixes``) as extra measurements, maximises the likelihood over the noise
figures (:mod:`accelnav.estimate.tune`) and writes the model with them, if they are significantly better
than the starting model's (likelihood-ratio test at 5 %); otherwise the starting figures are written back
and the report says so.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from accelnav.cli.core import INPUT_HELP, _input_args, print_review, read_args
from accelnav.errors import UserError
from accelnav.estimate.engine import Rests, rest_stage
from accelnav.estimate.tune import FIGURES, MAX_EVALUATIONS, TuneResult, aid_measurements, tune, with_figures
from accelnav.estimate.zupt import ZuptParams
from accelnav.model.edit import save_model
from accelnav.progress import Progress

MAX_SAMPLES = 500_000  # samples x axes: every likelihood evaluation runs filter and smoother (~340 B per sample)


def register(sub) -> None:
    p = sub.add_parser(
        "tune",
        help="estimate sigma_n, sigma_eps and R from a motion recording (maximum likelihood of the innovations)",
        description="Maximum-likelihood noise figures from a run with rests and/or position fixes; writes the "
        "model with them when they are significantly better than the starting model's.",
    )
    p.add_argument("run", type=Path, help=INPUT_HELP)
    _input_args(p)
    p.add_argument("--model", type=Path, default=None, help="starting model; default: the one in the run file")
    p.add_argument("--out", type=Path, required=True, metavar="OUT.toml", help="model file to write")
    p.add_argument("--fixes", type=Path, default=None, metavar="FILE", help="position fixes CSV (as for smooth)")
    p.add_argument(
        "--zupt",
        default=None,
        metavar="auto|FILE",
        help="rests: 'auto' detects them (the detector and per-rest gate of smooth --zupt auto); FILE is a "
        "ZUPT file as for smooth (intervals with optional axis and sigma columns, or a per-sample mask)",
    )
    p.add_argument("--zupt-sigma", type=float, default=ZuptParams().sigma, metavar="V", help="update std, m/s")
    p.add_argument(
        "--figures",
        default=",".join(FIGURES),
        help=f"comma-separated figures to tune, of {', '.join(FIGURES)}, c2 (every axis's constant bias); "
        f"default: {','.join(FIGURES)}",
    )
    p.add_argument(
        "--max-evaluations",
        type=int,
        default=MAX_EVALUATIONS,
        metavar="N",
        help="likelihood evaluations at most: the search (a third) and the profile intervals together; "
        f"default {MAX_EVALUATIONS}",
    )
    p.set_defaults(func=cmd_tune)


def cmd_tune(args: argparse.Namespace) -> int:
    from accelnav.estimate import zupt
    from accelnav.estimate.fixes import read_fixes

    figures = tuple(f.strip() for f in args.figures.split(",") if f.strip())
    bad = [f for f in figures if f not in FIGURES + ("c2",)] or ([] if figures else ["(none)"])
    if bad:
        raise UserError(
            f"--figures: {', '.join(bad)} unknown; accepted: a comma-separated subset of {', '.join(FIGURES)}, c2"
        )
    if args.max_evaluations < 10:
        raise UserError(f"--max-evaluations: got {args.max_evaluations}; accepted: 10 or more")
    if args.zupt_sigma <= 0:
        raise UserError(f"--zupt-sigma: got {args.zupt_sigma:g}; accepted: a standard deviation > 0 m/s")
    arrays, model = read_args(args)
    names = [str(a) for a in arrays["axis_names"]]
    accel = np.asarray(arrays["accel"], dtype=np.float64)
    valid = ~np.asarray(arrays["clipped"], dtype=bool)
    n, m = accel.shape
    if n * m > MAX_SAMPLES:
        raise UserError(
            f"{args.run}: {n} samples x {m} axes; accepted: at most {MAX_SAMPLES} (tune runs the filter a few "
            "hundred times: cut the run)"
        )
    fixes = read_fixes(args.fixes, arrays["t"], names) if args.fixes is not None else None
    rest = rest_sigma = params = None
    if args.zupt is not None:
        params = zupt.resolved(model, ZuptParams(sigma=args.zupt_sigma))
        if args.zupt == "auto":
            # the rest stage of smooth --zupt auto: decided once per rest for all axes, with the fixes, then the
            # rests a full smoother with the fixes or the other rests refutes dropped: they are not tuned to
            found = rest_stage(model, arrays, Rests(params, detect=True), fixes=fixes)
            rest = found.mask
            print_review(found.review)
        else:
            rest, rest_sigma = zupt.read_zupt_file(args.zupt, arrays["t"], names)
    extras, n_zupt = aid_measurements(n, m, model, fixes=fixes, rest=rest, rest_sigma=rest_sigma, params=params)
    n_fix = [len(e) - z for e, z in zip(extras, n_zupt, strict=True)]
    print(
        f"{args.run}: {n} samples, axes {', '.join(names)}; zero-velocity updates per axis "
        f"{', '.join(map(str, n_zupt))}; position fixes per axis {', '.join(map(str, n_fix))}"
    )
    if not any(extras) and "sigma_eps" in figures:
        print("  note: without rests or fixes the bias walk sigma_eps is hardly identifiable (see its interval)")
    with Progress("tune", total=args.max_evaluations + 20, unit="evaluations") as p:
        try:
            result = tune(
                model, accel, valid, extras, figures=figures, progress=p, max_evaluations=args.max_evaluations
            )
        except ValueError as exc:
            raise UserError(f"{args.run}: {exc}") from None
    print("\n".join(report(result)))
    out_model = with_figures(model, {f: float(f"{v:.6g}") for f, v in result.chosen.items()})
    save_model(args.out, out_model, header=provenance(args, result))  # whole or not at all
    print(f"model written to {args.out}")
    return 0


def report(r: TuneResult) -> list[str]:
    lines = ["| figure | start | estimate | 95 % interval | identified |", "|---|---|---|---|---|"]
    # noise figures: profile-likelihood intervals; c2: normal, from the observed information
    for f in r.start:
        if f in r.figures:
            why = r.why_not_identified(f)
            ident = "yes" if not why else f"NO: {why}"
            lines.append(f"| {f} | {r.start[f]:.4g} | {r.estimate[f]:.4g} | {_fmt_interval(r, f)} | {ident} |")
        else:
            if not f.startswith("c2."):
                lines.append(f"| {f} | {r.start[f]:.4g} | (kept) | | |")
    lines.append(
        f"ln L: start {r.ll_start:.6g}, estimate {r.ll_estimate:.6g}; improvement {r.ll_estimate - r.ll_start:.4g} "
        f"(likelihood ratio 2 dlnL = {r.lr:.4g}, p = {r.p_value:.3g} under the starting model, "
        f"chi-square with {len(r.figures)} dof); {r.evaluations} evaluations"
        + ("" if r.converged else " (the search stopped at its evaluation limit)")
    )
    if r.adopted:
        lines.append("-> the estimate is significantly better than the starting model (p < 0.05): written")
    else:
        lines.append("-> not significantly better than the starting model (p >= 0.05): the starting figures are kept")
    return lines


def _fmt_interval(r: TuneResult, f: str) -> str:
    """The 95 % interval; an open end of a profile interval is the search bound, marked as such."""
    lo, hi = r.ci95[f]
    ends = r.ends.get(f, ("closed", "closed"))
    a = f"{lo:.4g}" + (" (search bound)" if ends[0] == "open" else "")
    b = f"{hi:.4g}" + (" (search bound)" if ends[1] == "open" else "")
    return f"[{a}, {b}]"


def provenance(args, r: TuneResult) -> str:
    lines = [
        "accelnav model written by accelnav tune",
        f"run: {Path(args.run).name}; rests: {args.zupt or 'none'}; fixes: {args.fixes or 'none'}",
        f"ln L start {r.ll_start:.6g}, estimate {r.ll_estimate:.6g}, 2 dlnL = {r.lr:.4g}, p = {r.p_value:.3g}: "
        + ("estimate adopted" if r.adopted else "starting figures kept"),
    ]
    for f in r.figures:
        kind = "normal" if f.startswith("c2.") else "profile likelihood"
        lines.append(f"{f}: estimate {r.estimate[f]:.4g}, 95 % ({kind}) {_fmt_interval(r, f)}, start {r.start[f]:.4g}")
    return "\n".join(lines)
