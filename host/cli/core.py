"""``accelnav sim``, ``filter`` and ``smooth``: the simulate -> filter -> smooth chain on run files."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from accelnav.codegen.model import DEFAULT_MODEL, Model, load_model
from accelnav.data.runfile import STATE, export_csv, load_run, save_run
from accelnav.errors import UserError
from accelnav.estimate.pipeline import filter_run, format_errors, position_errors, smooth_run
from accelnav.estimate.zupt import ZuptParams


def _model_arg(p: argparse.ArgumentParser, help_extra: str = "") -> None:
    p.add_argument("--model", type=Path, default=None, help=f"model file (TOML){help_extra}")


def _csv_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--csv", type=Path, default=None, metavar="CSV", help="also export the samples as CSV")


def register(sub) -> None:
    p = sub.add_parser("sim", help="simulate a trajectory and the raw sensor output")
    _model_arg(p, f"; default: the embedded {DEFAULT_MODEL.name}")
    p.add_argument("--scenario", default="vehicle", help="trajectory (see --list-scenarios); default: vehicle")
    p.add_argument("--duration", type=float, default=60.0, help="seconds; default: 60")
    p.add_argument("--seed", type=int, default=1, help="random seed; default: 1")
    p.add_argument("--list-scenarios", action="store_true", help="print the scenario names and exit")
    p.add_argument("--out", type=Path, help="run file to write (.npz)")
    _csv_arg(p)
    p.set_defaults(func=cmd_sim)

    p = sub.add_parser("filter", help="run the float64 reference filter over a run file")
    p.add_argument("run", type=Path, help="run file (.npz) from accelnav sim")
    _model_arg(p, "; default: the model embedded in the run file")
    p.add_argument("--out", type=Path, required=True, help="run file to write (.npz)")
    _csv_arg(p)
    p.set_defaults(func=cmd_filter)

    p = sub.add_parser(
        "smooth",
        help="filter and RTS-smooth a run file (compiled), optionally with position fixes and zero-velocity updates",
        description="Float64 forward filter and RTS smoother per axis (accelnav.estimate.fastsmooth), agreeing "
        "with the reference of accelnav filter to 1e-9. Without --fixes and --zupt the plain path runs: gains "
        "computed once per model and run length, then a few operations per sample. Zero-velocity detection: "
        "accelnav.estimate.zupt.",
    )
    p.add_argument("run", type=Path, help="run file (.npz) from accelnav sim, filter or a recording")
    _model_arg(p, "; default: the model embedded in the run file")
    p.add_argument("--out", type=Path, required=True, help="run file to write (.npz)")
    p.add_argument(
        "--fixes",
        type=Path,
        default=None,
        metavar="FILE",
        help="position fixes, CSV with columns time_s,position_m,sigma_m (and axis for runs with several axes)",
    )
    p.add_argument(
        "--zupt",
        default=None,
        metavar="auto|FILE",
        help="zero-velocity updates: 'auto' detects rests in the acceleration; FILE is a CSV of rest "
        "intervals (start_s,end_s), applied without a gate",
    )
    z = ZuptParams()
    p.add_argument(
        "--zupt-window", type=float, default=z.window_s, metavar="S", help=f"detector window, s; default {z.window_s:g}"
    )
    p.add_argument(
        "--zupt-var-k",
        type=float,
        default=z.var_k,
        metavar="K",
        help=f"quiet if window variance <= K*R; default {z.var_k:g}",
    )
    p.add_argument(
        "--zupt-level",
        type=float,
        default=None,
        metavar="A",
        help="at rest if |window mean - bias| <= A m/s^2; default: from the model's bias uncertainty and R",
    )
    p.add_argument(
        "--zupt-sigma", type=float, default=z.sigma, metavar="V", help=f"update std, m/s; default {z.sigma:g}"
    )
    p.add_argument(
        "--zupt-every",
        type=float,
        default=z.every_s,
        metavar="S",
        help=f"one update per S s of rest; default {z.every_s:g}",
    )
    p.add_argument(
        "--zupt-gate",
        type=float,
        default=z.gate,
        metavar="G",
        help=f"chi-square gate of each update, 0 = none; default {z.gate:g}",
    )
    p.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write PNG plots into DIR")
    _csv_arg(p)
    p.set_defaults(func=cmd_smooth)


def require_scenario(name: str) -> None:
    """UserError for a --scenario the simulator does not have (shared by sim, hil and demo)."""
    from accelnav.hil_sim.trajectories import ALL_SCENARIOS as SCENARIOS

    if name not in SCENARIOS:
        raise UserError(f"--scenario: unknown scenario {name!r}; accepted: {', '.join(SCENARIOS)}")


def _simulate(model: Model, scenario: str, duration: float, seed: int) -> dict[str, np.ndarray]:
    from accelnav.hil_sim.sensor import simulate

    require_scenario(scenario)
    try:
        run = simulate(model, scenario, duration, seed)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    return run.to_arrays()


def _load(args) -> tuple[dict[str, np.ndarray], Model]:
    arrays, model = load_run(args.run)
    if args.model is not None:
        override = load_model(args.model)
        if [a.name for a in override.axes] != [str(a) for a in arrays["axis_names"]]:
            raise UserError(
                f"{args.model}: axes {[a.name for a in override.axes]} do not match the run's "
                f"{[str(a) for a in arrays['axis_names']]}"
            )
        model = override
    return arrays, model


def _save(args, arrays, model) -> None:
    save_run(args.out, arrays, model)
    print(f"wrote {args.out}")
    if args.csv is not None:
        export_csv(args.csv, arrays)
        print(f"wrote {args.csv}")


def _summary(arrays: dict[str, np.ndarray]) -> str:
    n = len(arrays["t"])
    dur = arrays["t"][-1] - arrays["t"][0] if n > 1 else 0.0
    lines = [f"{n} samples, {dur:.2f} s, axes {', '.join(str(a) for a in arrays['axis_names'])}"]
    for j, name in enumerate(str(a) for a in arrays["axis_names"]):
        parts = [f"axis {name}: {int(arrays['clipped'][:, j].sum())} clipped"]
        for stage in ("filt", "smooth"):
            if f"{stage}_x" in arrays:
                k = -1 if stage == "filt" else 0
                x = arrays[f"{stage}_x"][j, k]
                sd = np.sqrt(np.diag(arrays[f"{stage}_P"][j, k]))
                at = "end" if k == -1 else "start"
                est = ", ".join(f"{s}={v:.4g}+-{e:.2g}" for s, v, e in zip(STATE, x, sd, strict=True))
                parts.append(f"{'filter' if stage == 'filt' else 'smoother'} at {at}: {est}")
        lines.append("; ".join(parts))
    return "\n".join(lines)


def cmd_sim(args) -> int:
    if args.list_scenarios:
        from accelnav.hil_sim.trajectories import ALL_SCENARIOS as SCENARIOS

        print("\n".join(SCENARIOS))
        return 0
    if args.out is None:
        raise UserError("--out: a run file to write is required")
    model = load_model(args.model)
    arrays = _simulate(model, args.scenario, args.duration, args.seed)
    print(_summary(arrays))
    _save(args, arrays, model)
    return 0


def cmd_filter(args) -> int:
    arrays, model = _load(args)
    arrays = filter_run(arrays, model)
    print(_summary(arrays))
    rows = position_errors(arrays, model)
    if rows:
        print(format_errors(rows))
    _save(args, arrays, model)
    return 0


def cmd_smooth(args) -> int:
    from accelnav.estimate import zupt
    from accelnav.estimate.fixes import read_fixes

    arrays, model = _load(args)
    names = [str(a) for a in arrays["axis_names"]]
    fixes = read_fixes(args.fixes, arrays["t"], names) if args.fixes is not None else None
    params = ZuptParams(
        window_s=args.zupt_window,
        var_k=args.zupt_var_k,
        level=args.zupt_level,
        sigma=args.zupt_sigma,
        every_s=args.zupt_every,
        gate=args.zupt_gate,
    )
    rest = None
    if args.zupt == "auto":
        try:
            params = zupt.resolved(model, params)
        except ValueError as exc:
            raise UserError(f"--zupt-*: {exc}") from None
        rest = zupt.rest_mask(arrays["accel"], arrays["clipped"], model, params)
        print(
            f"zero-velocity detector: window {params.window_s:g} s, variance <= {params.var_k:g} R, "
            f"|mean - bias| <= {params.level:.3g} m/s^2: {len(zupt.intervals(rest))} rests, "
            f"{100 * rest.mean():.1f} % of the run"
        )
    elif args.zupt is not None:
        rest = zupt.intervals_from_csv(args.zupt, arrays["t"])
    arrays = smooth_run(arrays, model, fixes=fixes, rest=rest, zupt_params=params, zupt_gated=args.zupt == "auto")
    if rest is not None:
        print(f"zero-velocity updates applied per axis: {', '.join(str(int(c)) for c in arrays['zupt'].sum(axis=0))}")
    if fixes is not None:
        print(f"position fixes per axis: {', '.join(str(len(f)) for f in fixes)}")
    print(_summary(arrays))
    rows = position_errors(arrays, model)
    if rows:
        print(format_errors(rows))
    _save(args, arrays, model)
    if args.plots is not None:
        from accelnav.plots.run import plot_run, plot_smoothing

        print(f"wrote {plot_run(arrays, model, args.plots / 'smooth.png')}")
        for path in plot_smoothing(arrays, model, args.plots):
            print(f"wrote {path}")
    return 0
