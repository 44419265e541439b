"""``accelnav sim``, ``filter`` and ``smooth``: the simulate -> filter -> smooth chain on run files."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np

from accelnav.api import simulate
from accelnav.cli.args import clock_args, reader_options
from accelnav.data.inputs import read_input
from accelnav.data.runfile import FORMAT, STATE, export_csv, save_run, state_sd
from accelnav.errors import UserError
from accelnav.estimate.chunked import memory_available, whole_bytes
from accelnav.estimate.pipeline import (
    disagreeing_rests,
    filter_run,
    format_errors,
    format_strides,
    position_errors,
    smooth_run,
    stride_table,
    truth_versus_baselines,
)
from accelnav.estimate.zupt import ZuptParams
from accelnav.fileio import check_output, write_text
from accelnav.model.load import DEFAULT_MODEL, Model, load_model
from accelnav.progress import note

TUNE_EVALUATIONS = 300  # smooth --tune: the estimate only (no intervals): a few hundred filter runs
TUNE_SECONDS = 60.0


def _model_arg(p: argparse.ArgumentParser, help_extra: str = "") -> None:
    p.add_argument("--model", type=Path, default=None, help=f"model file (TOML){help_extra}")


INPUT_HELP = (
    "the data: an accelnav run file (.npz), a recorder log (.acnlog), a CSV or gzip CSV with a time column "
    "and one column per axis, or an NPZ with t and accel"
)


def _input_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--axis",
        action="append",
        metavar="NAME",
        help="CSV/NPZ: a column to use as an axis, in the model's axis order; repeat for each axis",
    )
    p.add_argument("--time-column", default=None, metavar="NAME", help="CSV: the time column; default t, t_s, time")
    clock_args(p)
    p.add_argument(
        "--unit",
        default=None,
        help="CSV: unit of the acceleration columns, g, mg, m/s^2 or counts (raw codes, converted by the model's "
        "own read-out and calibration); default: from the column names, else counts for an analog model, else "
        "the unit of a calibrated model",
    )
    p.add_argument(
        "--allow-gaps",
        action="store_true",
        help="accept gaps in time: the missing samples are filled in and the filter only predicts across them",
    )


def _csv_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--csv", type=Path, default=None, metavar="CSV", help="also export the samples as CSV")


def _output_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--covariances",
        action="store_true",
        help="also write the full 4x4 covariances and the filter's priors (default: the states and their "
        "standard deviations; the covariances are two thirds of the file)",
    )
    p.add_argument("--compress", action="store_true", help="deflate the run file (smaller, several times slower)")


def register(sub) -> None:
    p = sub.add_parser("sim", help="simulate a trajectory and the raw sensor output")
    _model_arg(p, f"; default: the embedded {DEFAULT_MODEL.name}")
    p.add_argument("--scenario", default="vehicle", help="trajectory (see --list-scenarios); default: vehicle")
    p.add_argument("--duration", type=float, default=60.0, help="seconds; default: 60")
    p.add_argument("--seed", type=int, default=1, help="random seed; default: 1")
    p.add_argument("--list-scenarios", action="store_true", help="print the scenario names and exit")
    p.add_argument("--out", type=Path, help="run file to write (.npz)")
    _csv_arg(p)
    p.add_argument(
        "--fixes-out",
        type=Path,
        default=None,
        metavar="CSV",
        help="also write the scenario's position fixes (highway_gnss, town_drive, hand_box) as the CSV "
        "smooth --fixes reads",
    )
    p.set_defaults(func=cmd_sim)

    p = sub.add_parser(
        "filter",
        help="run the forward filter (compiled, float64) over a recording or run file",
        description="Float64 forward filter per axis (accelnav.estimate.fastsmooth), agreeing with the reference "
        "accelnav.estimate.kf to 1e-9.",
    )
    p.add_argument("run", type=Path, help=INPUT_HELP)
    _model_arg(p, "; default: the model embedded in the input, else the embedded default")
    _input_args(p)
    p.add_argument("--out", type=Path, required=True, help="run file to write (.npz)")
    _output_args(p)
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
    p.add_argument("run", type=Path, help=INPUT_HELP)
    _model_arg(p, "; default: the model embedded in the input, else the embedded default")
    _input_args(p)
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
        help="zero-velocity updates: 'auto' detects rests in the acceleration (accelnav.estimate.zupt); FILE is a "
        "CSV of rest intervals (start_s,end_s[,axis][,sigma]) or a per-sample 0/1 mask (NPZ key 'rest', or a CSV "
        "column 'rest'), applied as given",
    )
    z = ZuptParams()
    zupt_opts = [
        ("--zupt-window", "window_s", "S", f"detector window, s; default {z.window_s:g}"),
        (
            "--zupt-var-k",
            "var_k",
            "K",
            f"quiet if the window variance over (R + tremor^2), averaged over axes, <= K; default {z.var_k:g}",
        ),
        (
            "--zupt-tremor",
            "tremor",
            "A",
            f"rms motion of a body at rest (a stance's sway, an idling engine), m/s^2; default {z.tremor:g}",
        ),
        (
            "--zupt-level",
            "level_still",
            "A",
            f"a rest's level may differ from the last rest's by A m/s^2 when nothing moved between; default "
            f"{z.level_still:g}",
        ),
        (
            "--zupt-level-max",
            "level_max",
            "A",
            f"... and by A m/s^2 after a move (a jog's or a tilting mount's leak); default {z.level_max:g}",
        ),
        (
            "--zupt-level-walk",
            "level_walk",
            "A",
            f"random walk of the level between aids, m/s^2 per sqrt(s); default {z.level_walk:g}",
        ),
        (
            "--zupt-tell",
            "tell",
            "V",
            f"the fixes or the other rests can tell a rest when the sd of its velocity is <= V m/s; default {z.tell:g}",
        ),
        (
            "--zupt-trim",
            "trim_k",
            "K",
            f"a rest ends where its window mean is K sd off its own level; default {z.trim_k:g}",
        ),
        (
            "--zupt-still",
            "still_k",
            "K",
            f"a still start or stand (when nothing else can tell): variance <= K R; default {z.still_k:g}",
        ),
        (
            "--zupt-drift",
            "drift",
            "A",
            f"mean acceleration error between aids that no level explains, m/s^2 (widens the test); "
            f"default {z.drift:g}",
        ),
        (
            "--zupt-scale",
            "scale",
            "F",
            f"share of the acceleration integrated since the last aid that may be error (widens the test); "
            f"default {z.scale:g}",
        ),
        ("--zupt-sigma", "sigma", "V", f"update std, m/s; default {z.sigma:g}"),
        ("--zupt-every", "every_s", "S", "one update per S s of rest; default 0: every sample"),
        (
            "--zupt-gate",
            "gate",
            "G",
            f"a rest is refused as moving when the velocity the fixes or the other rests give it, before or after "
            f"it, has a chi-square over the axes above G on one axis' scale (9: 3 sd); 0 = accept every "
            f"candidate; default {z.gate:g}",
        ),
        (
            "--zupt-rel",
            "rel",
            "F",
            f"a still stand (when nothing else can tell): the speed since the last rest came back to F of its peak; "
            f"default {z.rel:g}",
        ),
    ]
    for flag, field, metavar, text in zupt_opts:
        p.add_argument(flag, type=float, default=getattr(z, field), dest=f"zupt_{field}", metavar=metavar, help=text)
    p.add_argument(
        "--zupt-report",
        type=Path,
        default=None,
        metavar="FILE.csv",
        help="with --zupt auto: one CSV row per candidate rest (start_s, end_s, samples, decision, reason, "
        "the statistics it was judged on)",
    )
    p.add_argument(
        "--tune",
        action="store_true",
        help="first fit sigma_n, sigma_eps and R to this recording (maximum likelihood of the innovations, as "
        "accelnav tune, using its fixes and rests), then smooth with them",
    )
    p.add_argument(
        "--tune-evaluations",
        type=int,
        default=TUNE_EVALUATIONS,
        metavar="N",
        help=f"--tune: likelihood evaluations at most; default {TUNE_EVALUATIONS}",
    )
    p.add_argument(
        "--tune-seconds",
        type=float,
        default=TUNE_SECONDS,
        metavar="S",
        help=f"--tune: wall time of the search at most (the best figures by then are used); default {TUNE_SECONDS:g}",
    )
    p.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write PNG plots into DIR")
    p.add_argument(
        "--filter-states",
        action="store_true",
        help="also write the forward filter's states filt_x, filt_sd when the run streams (by default it writes "
        "the smoother's alone: the filter's doubled the file and its writing time; accelnav filter writes "
        "them, and runs that keep every sample in memory (--plots, --covariances, aids, ...) always do)",
    )
    p.add_argument(
        "--warm-start",
        action="store_true",
        help="the recording begins after the warm-up, not at power-on: the bias starts at its settled value "
        "c1 + c2 instead of c2",
    )
    p.add_argument(
        "--memory-budget",
        type=float,
        default=None,
        metavar="MB",
        help="memory the whole-array smoother may take; a longer run is smoothed in bounded memory (chunks, a "
        "store on disk beside --out; not with --tune, --plots, --csv; the output keeps standard deviations, "
        "not covariances, and the aids' consistency checks are skipped); default: half the memory free",
    )
    _output_args(p)
    _csv_arg(p)
    p.set_defaults(func=cmd_smooth)


def write_outputs(args, arrays, model) -> None:
    save_run(args.out, arrays, model, compress=getattr(args, "compress", False))
    print(f"wrote {args.out}")
    if args.csv is not None:
        export_csv(args.csv, arrays)
        print(f"wrote {args.csv}")


def _summary(arrays: dict[str, np.ndarray], n: int | None = None) -> str:
    """``n``: the run's samples when ``arrays`` hold only its ends (t first and last, clipped counts)."""
    n = len(arrays["t"]) if n is None else n
    dur = arrays["t"][-1] - arrays["t"][0] if n > 1 else 0.0
    lines = [f"{n} samples, {dur:.2f} s, axes {', '.join(str(a) for a in arrays['axis_names'])}"]
    for j, name in enumerate(str(a) for a in arrays["axis_names"]):
        parts = [f"axis {name}: {int(arrays['clipped'][:, j].sum())} clipped"]
        for stage in ("filt", "smooth"):
            if f"{stage}_x" in arrays:
                k = -1 if stage == "filt" else 0
                x = arrays[f"{stage}_x"][j, k]
                sd = state_sd(arrays, stage)[j, k]
                at = "end" if k == -1 else "start"
                # a state known exactly (r = u = 0 at the start, by the filter's prior) has no estimate to show
                known = [s for s, v, e in zip(STATE, x, sd, strict=True) if e == 0 and v == 0]
                est = ", ".join(f"{s}={v:.4g}+-{e:.2g}" for s, v, e in zip(STATE, x, sd, strict=True) if s not in known)
                if known:
                    est += f" ({' = '.join(known)} = 0 there by definition)"
                parts.append(f"{'filter' if stage == 'filt' else 'smoother'} at {at}: {est}")
        lines.append("; ".join(parts))
    return "\n".join(lines)


def read_args(args) -> tuple[dict[str, np.ndarray], Model]:
    """read_input with the command's flags; outputs that cannot be written are refused before the work."""
    for flag in ("out", "csv"):
        if getattr(args, flag, None) is not None:
            check_output(getattr(args, flag), f"--{flag}")
    return read_input(args.run, args.model, allow_gaps=args.allow_gaps, **reader_options(args))


def _csv_size_args(args) -> tuple[int, int] | None:
    """(estimated rows, axes) of a plain CSV input, from its size and first lines; None for another input."""
    from accelnav.data.stream import estimate_rows

    rows = estimate_rows(args.run)
    if rows is None:
        return None
    return rows, len(args.axis) if args.axis else len(load_model(args.model).axes)


def _whole_input_args(args, why: str) -> None:
    """Refuse, before reading it, a CSV whose numbers exceed what one input may hold in memory."""
    from accelnav.fileio import input_limit

    size = _csv_size_args(args)
    if size is None:
        return
    rows, n_axes = size
    need, limit = rows * 8 * (2 + n_axes), input_limit()
    if need > limit:
        raise UserError(
            f"{args.run}: about {rows} rows x {n_axes} axes need about {need / 1e9:.3g} GB in memory; {why} and "
            f"may take {limit / 1e9:.3g} GB here (ACCELNAV_MAX_INPUT_BYTES); plain smooth streams any length"
        )


def stream_args(args, budget: int):
    """A CSV input smoothed in bounded memory, opened as a stream (accelnav.data.stream) before anything is
    read whole, or None: read it whole (not a CSV, within the budget, or not streamed: see NotStreamed).

    Decided from the file's size: the whole-array smoother's memory against ``budget``. Only the plain
    smoother streams; the aids (--fixes, --zupt, --tune) and --plots, --csv, --covariances need every
    sample in memory, so with them an input that cannot be held is refused here in one line."""
    from accelnav.data.stream import NotStreamed, open_stream
    from accelnav.estimate.chunked import disk_needed

    size = _csv_size_args(args)
    if size is None or whole_bytes(*size) <= budget:
        return None
    flags = (("--fixes", args.fixes), ("--zupt", args.zupt), ("--tune", args.tune), ("--plots", args.plots),
             ("--csv", args.csv), ("--covariances", args.covariances))  # fmt: skip
    if any(v for _, v in flags):
        _whole_input_args(args, f"{', '.join(f for f, v in flags if v)} need(s) every sample in memory, which")
        return None
    for flag in ("out", "csv"):
        if getattr(args, flag, None) is not None:
            check_output(getattr(args, flag), f"--{flag}")
    rows, n_axes = size
    workdir = Path(args.out).resolve().parent
    need = rows * 8 * (2 + n_axes) + disk_needed(
        rows, n_axes, n_stages=1 + bool(args.filter_states)
    )  # input store + smoother
    free = shutil.disk_usage(workdir).free
    if need > free:
        raise UserError(
            f"{args.run}: about {rows} rows x {n_axes} axes need about {need / 1e9:.3g} GB of disk in {workdir} "
            f"to be smoothed in bounded memory; {free / 1e9:.3g} GB are free"
        )
    try:
        return open_stream(
            args.run, args.model, axes=args.axis, time_column=args.time_column, rate_hz=args.rate,
            time_unit=args.time_unit, unit=args.unit, allow_gaps=args.allow_gaps, workdir=workdir,
        )  # fmt: skip
    except NotStreamed as exc:
        note(f"{exc}; reading it whole")
        return None


def _smooth_streamed(args, stream) -> int:
    """Plain smooth of a streamed CSV: its rows go from the store to the chunked smoother, never all in memory;
    the same stages, store and summary as _cmd_streamed, which takes a run held in memory."""
    from accelnav.estimate.chunked import BUDGET, smooth_bounded

    clipped: dict[int, np.ndarray] = {}

    def read(s: int, e: int):
        t, accel, c = stream(s, e)
        clipped[s] = c.sum(axis=0)  # by chunk start: a chunk read twice counts once
        return t, accel, c

    with stream:
        model = stream.model
        if args.warm_start:
            from accelnav.model.edit import warm_started

            model = warm_started(model)
            note("--warm-start: bias prior at c1 + c2 = " + ", ".join(f"{a.c2:.4g}" for a in model.axes) + " m/s^2")
        budget = _memory_budget_arg(args.memory_budget)
        stages = ("filt", "smooth") if args.filter_states else ("smooth",)
        info = smooth_bounded(
            model, stream.n, read, args.out, axis_names=stream.axis_names, run_format=FORMAT, stages=stages,
            budget=min(BUDGET, budget), store_memory=budget,
        )  # fmt: skip
        ends = {k: v[:, None, :] for k, v in info["last"].items() if k.startswith("filt_")}
        ends.update({k: v[:, None, :] for k, v in info["first"].items() if k.startswith("smooth_")})
        t_ends = np.array([stream.t0, stream.t0 + (stream.n - 1) * stream.Ts])
        counts = np.sum(list(clipped.values()), axis=0)[None, :]
        print(_summary({"t": t_ends, "axis_names": stream.axis_names, "clipped": counts, **ends}, n=stream.n))
    where = "in memory" if info["store_in_memory"] else f"on disk beside {args.out}"
    print(
        f"{args.run}: streamed from the CSV (its numbers in a store on disk while it ran) and smoothed in bounded "
        f"memory: {info['chunks']} chunks of {info['chunk']} samples, the smoother's store {where}"
    )
    print(f"wrote {args.out}")
    return 0


def cmd_sim(args) -> int:
    if args.list_scenarios:
        from accelnav.hil_sim.sim.trajectories import ALL_SCENARIOS as SCENARIOS

        print("\n".join(SCENARIOS))
        return 0
    if args.out is None:
        raise UserError("--out: a run file to write is required")
    from accelnav.hil_sim.sim.trajectories import FIX_PLANS, require_scenario

    model = load_model(args.model)
    require_scenario(args.scenario, "--scenario", UserError)
    if args.fixes_out is not None and args.scenario not in FIX_PLANS:
        raise UserError(
            f"--fixes-out: scenario {args.scenario!r} has no position fixes; those with fixes: {', '.join(FIX_PLANS)}"
        )
    if args.fixes_out is not None:
        check_output(args.fixes_out, "--fixes-out")
    arrays = simulate(model, args.scenario, args.duration, args.seed)
    print(_summary(arrays))
    write_outputs(args, arrays, model)
    if args.fixes_out is not None:
        from accelnav.estimate.fixes import fixes_csv

        write_text(args.fixes_out, fixes_csv(arrays["sim_fixes"], arrays["axis_names"]), flag="--fixes-out")
        print(f"wrote {args.fixes_out} ({len(arrays['sim_fixes'])} position fixes)")
    return 0


# keys of a run the streaming path writes again (the recording's) or recomputes (a previous stage's output)
_STREAM_KEYS = {"t", "accel", "clipped", "axis_names", "format", "model_toml", "model_source"}
_STAGE_KEYS = ("filt_", "smooth_", "zupt", "fixes", "fix_nis")


def _stream_args(args, arrays: dict[str, np.ndarray]) -> bool:
    """Plain filtering or smoothing streams through the chunked kernels (accelnav.estimate.chunked: the
    input read once, the output written once, in place, at any length) unless a feature needs every
    sample in memory: covariances, CSV export, compression, and keys of the input the run file keeps
    (raw codes, a simulation's truth, which the truth tables print)."""
    if args.covariances or args.csv is not None or getattr(args, "compress", False):
        return False
    return all(k in _STREAM_KEYS or k.startswith(_STAGE_KEYS) for k in arrays)


def _cmd_streamed(args, arrays: dict[str, np.ndarray], model: Model, stages: tuple[str, ...]) -> int:
    """filter or smooth of a plain run in chunks; the same numbers as the whole-array path (to 1e-12)."""
    from accelnav.estimate.chunked import BUDGET, array_reader, smooth_bounded

    n = len(arrays["t"])
    read = array_reader(arrays["t"], arrays["accel"], arrays["clipped"])
    budget = _memory_budget_arg(getattr(args, "memory_budget", None))
    info = smooth_bounded(
        model, n, read, args.out, axis_names=arrays["axis_names"], run_format=FORMAT, stages=stages,
        budget=min(BUDGET, budget), store_memory=budget,
    )  # fmt: skip
    ends = {k: v[:, None, :] for k, v in info["last"].items() if k.startswith("filt_")}
    ends.update({k: v[:, None, :] for k, v in info["first"].items() if k.startswith("smooth_")})
    print(_summary({"t": arrays["t"], "axis_names": arrays["axis_names"], "clipped": arrays["clipped"], **ends}))
    where = "in memory" if info["store_in_memory"] else f"on disk beside {args.out}"
    store = f", the store {where}" if "smooth" in stages else ""
    print(f"streamed in bounded memory: {info['chunks']} chunks of {info['chunk']} samples{store}")
    print(f"wrote {args.out}")
    return 0


def cmd_filter(args) -> int:
    _whole_input_args(args, "filter holds the run in memory")
    arrays, model = read_args(args)
    if _stream_args(args, arrays):
        return _cmd_streamed(args, arrays, model, ("filt",))
    arrays = filter_run(arrays, model, covariances=args.covariances)
    print(_summary(arrays))
    rows = position_errors(arrays, model)
    if rows:
        print(format_errors(rows))
    write_outputs(args, arrays, model)
    return 0


def _zupt_summary(decisions, params: ZuptParams, rest: np.ndarray, gravity: list[str] = ()) -> str:
    """One line: the detector's settings, candidates, accepted and refused with their counts per reason;
    when none was accepted and an axis carries gravity (``gravity``, zupt.gravity_axes), it says so."""
    from accelnav.estimate import zupt

    counts = zupt.reason_counts(decisions)
    acc = {r: c for r, c in counts.items() if r in zupt.ACCEPT_REASONS}
    ref = {r: c for r, c in counts.items() if r in zupt.REFUSE_REASONS}

    def listed(d: dict[str, int]) -> str:
        return f" ({', '.join(f'{r} {c}' for r, c in d.items())})" if d else ""

    start = next((d for d in decisions if d.reason == "still start"), None)
    cannot = next((d for d in decisions if d.reason == "cannot tell"), None)
    why = ""
    if start is not None:
        why += f"; {start.evidence}"
    if not acc and cannot is not None:
        why += (
            f"; no rest could be told ({cannot.evidence.split(';')[0]}): position fixes (--fixes), or a still "
            f"start of {params.start_s:g} s, would give one"
        )
    return (
        f"zero-velocity detector: window {params.window_s:g} s, variance <= {params.var_k:g} (R + "
        f"{params.tremor:g}^2): {len(decisions)} candidate rests, {sum(acc.values())} accepted{listed(acc)}, "
        f"{sum(ref.values())} refused{listed(ref)}; {100 * rest.mean():.1f} % of the run at rest{why}"
        + (
            f"; axis {', '.join(gravity)} reads about 1 g (gravity), which the model takes as removed: "
            "drop it with --axis (the others' names)"
            if gravity and not acc
            else ""
        )
    )


def cmd_smooth(args) -> int:
    from accelnav.estimate import zupt
    from accelnav.estimate.fixes import read_fixes

    stream = stream_args(args, _memory_budget_arg(args.memory_budget))
    if stream is not None:
        return _smooth_streamed(args, stream)
    arrays, model = read_args(args)
    if args.warm_start:  # the same for every path below (bounded, --tune, the aids' checks) and the run file
        from accelnav.model.edit import warm_started

        model = warm_started(model)
        note("--warm-start: bias prior at c1 + c2 = " + ", ".join(f"{a.c2:.4g}" for a in model.axes) + " m/s^2")
    budget = _memory_budget_arg(args.memory_budget)
    bounded = whole_bytes(*arrays["accel"].shape) > budget
    if bounded:  # what the bounded path cannot do is refused before any work
        _bounded_args(args, arrays, budget)
    names = [str(a) for a in arrays["axis_names"]]
    fixes = read_fixes(args.fixes, arrays["t"], names) if args.fixes is not None else None
    params = ZuptParams(
        window_s=args.zupt_window_s,
        var_k=args.zupt_var_k,
        tremor=args.zupt_tremor,
        level_still=args.zupt_level_still,
        level_max=args.zupt_level_max,
        level_walk=args.zupt_level_walk,
        tell=args.zupt_tell,
        drift=args.zupt_drift,
        scale=args.zupt_scale,
        trim_k=args.zupt_trim_k,
        still_k=args.zupt_still_k,
        sigma=args.zupt_sigma,
        every_s=args.zupt_every_s,
        gate=args.zupt_gate,
        rel=args.zupt_rel,
    )
    if args.zupt_report is not None and args.zupt != "auto":
        raise UserError("--zupt-report: only with --zupt auto (it lists the detector's candidates)")
    rest = rest_sigma = None
    if args.zupt is not None:
        try:
            params = zupt.resolved(model, params)
        except ValueError as exc:
            raise UserError(f"--zupt-*: {exc}") from None
    if args.zupt == "auto":
        found = zupt.decide_rests(arrays["accel"], arrays["clipped"], None, model, params, fixes)
        decisions, rest = found.decisions, found.mask
        gravity = zupt.gravity_axes(arrays["accel"], arrays["clipped"], model) if not rest.any() else []
        print(_zupt_summary(decisions, params, rest, gravity))
        if args.zupt_report is not None:
            write_text(args.zupt_report, zupt.report_csv(decisions, arrays["t"]), flag="--zupt-report")
            print(f"wrote {args.zupt_report}")
    elif args.zupt is not None:
        rest, rest_sigma = zupt.read_zupt_file(args.zupt, arrays["t"], names)
    if fixes is None and rest is None and not args.tune and args.plots is None and _stream_args(args, arrays):
        return _cmd_streamed(args, arrays, model, ("filt", "smooth") if args.filter_states else ("smooth",))
    if bounded:
        return _smooth_bounded(args, arrays, model, budget, fixes, rest, rest_sigma, params)
    # automatic rests that disagree with the rest of the evidence go first, before tuning and any advice
    review = disagreeing_rests(arrays, model, rest, fixes=fixes, params=params) if args.zupt == "auto" else None
    rest = rest if review is None else review.kept
    print_review(review)
    if args.tune:
        model = _smooth_tune(args, arrays, model, fixes, rest, rest_sigma, params)
    inputs = arrays
    arrays = smooth_run(
        arrays, model, fixes=fixes, rest=rest, zupt_params=params, rest_sigma=rest_sigma, covariances=args.covariances
    )
    if args.zupt == "auto":  # kept in the run file for the plots: [start_s, end_s, accepted] per candidate
        t = arrays["t"]
        arrays["zupt_candidates"] = np.array(
            [[t[d.start], t[d.stop - 1], float(d.accepted and rest[d.start : d.stop].any())] for d in decisions],
            dtype=np.float64,
        ).reshape(-1, 3)
    if rest is not None:
        print(f"zero-velocity updates applied per axis: {', '.join(str(int(c)) for c in arrays['zupt'].sum(axis=0))}")
    if fixes is not None:
        print(f"position fixes per axis: {', '.join(str(len(f)) for f in fixes)}")
    smooth_kw = dict(rest=rest, zupt_params=params, rest_sigma=rest_sigma)
    checks = print_checks(arrays, model, inputs, fixes, smooth_kw, tuned=args.tune)
    print(_summary(arrays))
    _print_truth(arrays, model, checks)
    strides = stride_table(arrays, model)
    if strides:
        print(format_strides(strides))
    write_outputs(args, arrays, model)
    if args.plots is not None:
        from accelnav.plots.run import plot_run, plot_smoothing

        print(f"wrote {plot_run(arrays, model, args.plots / 'smooth.png')}")
        for path in plot_smoothing(arrays, model, args.plots):
            print(f"wrote {path}")
    return 0


def _print_truth(arrays, model: Model, checks) -> None:
    """With truth: the error table, and a line if the smoother loses to a fix-only baseline."""
    rows = position_errors(arrays, model)
    if rows:
        print(format_errors(rows))
        line = truth_versus_baselines(rows, checks.tune_helps)
        if line:
            print(line)


def _memory_budget_arg(mb: float | None) -> int:
    if mb is None:
        return memory_available() // 2
    if not mb > 0:
        raise UserError(f"--memory-budget: got {mb:g}; accepted: megabytes > 0")
    return int(mb * (1 << 20))


def format_over_budget(args, arrays, budget: int) -> str:
    n, n_axes = arrays["accel"].shape
    return (
        f"{args.run}: {n} samples x {n_axes} axes need about {whole_bytes(n, n_axes) / 1e9:.3g} GB on the "
        f"whole-array path, over the memory budget of {budget / 1e9:.3g} GB (--memory-budget)"
    )


def _bounded_args(args, arrays, budget: int) -> None:
    flags = (("--plots", args.plots), ("--csv", args.csv), ("--tune", args.tune), ("--covariances", args.covariances))
    given = [f for f, v in flags if v]
    if given:
        raise UserError(f"{format_over_budget(args, arrays, budget)}; bounded memory does not do {', '.join(given)}")


def _smooth_bounded(args, arrays, model: Model, budget: int, fixes, rest, rest_sigma, params) -> int:
    """smooth of a run over the memory budget, in chunks with a store on disk (accelnav.estimate.chunked)."""
    from accelnav.estimate import zupt
    from accelnav.estimate.chunked import BUDGET, array_reader, smooth_bounded
    from accelnav.estimate.kf import Aids

    n, n_axes = arrays["accel"].shape
    fix_lists = [list(fixes[j]) if fixes is not None else [] for j in range(n_axes)]
    extras = [Aids.of(f) for f in fix_lists]  # fixes first, then the rests' updates, as arrays (no object each)
    zupt_ks = [np.zeros(0, dtype=np.int64)] * n_axes
    if rest is not None:
        r2 = np.broadcast_to(rest[:, None] if rest.ndim == 1 else rest, (n, n_axes))
        for j in range(n_axes):
            sigma = None if rest_sigma is None else np.asarray(rest_sigma)[:, j]
            za = zupt.axis_aids(r2[:, j], sigma, model, params)
            zupt_ks[j] = za.k
            extras[j] = extras[j].concat(za)
    gates = [np.zeros(len(e)) for e in extras]
    n_fix = [len(f) for f in fix_lists]

    def more(applied: list[np.ndarray]) -> dict[str, np.ndarray]:
        """The run file's zupt mask and fixes rows, as the whole-array path writes them."""
        mask = np.zeros((n, n_axes), dtype=bool)
        for j in range(n_axes):
            mask[zupt_ks[j][applied[j][n_fix[j] :]], j] = True
        rows = [(arrays["t"][m.k], j, m.z, np.sqrt(m.R)) for j in range(n_axes) for m in fix_lists[j]]
        return {"zupt": mask, "fixes": np.array(rows, dtype=np.float64).reshape(-1, 4)}

    read = array_reader(arrays["t"], arrays["accel"], arrays["clipped"])
    info = smooth_bounded(
        model, n, read, args.out, axis_names=arrays["axis_names"], extras=extras, gates=gates,
        budget=min(BUDGET, budget), run_format=FORMAT, more=more,
    )  # fmt: skip
    print(
        f"{format_over_budget(args, arrays, budget)}: smoothed in bounded memory, {info['chunks']} chunks of "
        f"{info['chunk']} samples with a store on disk; the output has standard deviations (filt_sd, smooth_sd), "
        "not covariances, and no consistency checks"
    )
    if rest is not None:
        counts = [int(a[k:].sum()) for a, k in zip(info["applied"], n_fix, strict=True)]
        print(f"zero-velocity updates applied per axis: {', '.join(map(str, counts))}")
    if fixes is not None:
        print(f"position fixes per axis: {', '.join(str(len(f)) for f in fixes)}")
    print(f"wrote {args.out}")
    return 0


def _smooth_tune(args, arrays, model: Model, fixes, rest, rest_sigma, params) -> Model:
    """smooth --tune: its flags checked, the search run (estimate.tune.tune_run), its two lines printed."""
    import time

    from accelnav.estimate.tune import FIGURES, tune_run

    if args.tune_evaluations < 10:
        raise UserError(f"--tune-evaluations: got {args.tune_evaluations}; accepted: 10 or more")
    if not args.tune_seconds > 0:
        raise UserError(f"--tune-seconds: got {args.tune_seconds:g}; accepted: a time > 0 s")
    t0 = [time.monotonic()]

    def announce(n: int, m: int, aids: int) -> None:
        print(
            f"tune: fitting {', '.join(FIGURES)} to {n} samples x {m} axes with {aids} aids; budget "
            f"{args.tune_evaluations} evaluations, {args.tune_seconds:g} s"
        )
        t0[0] = time.monotonic()

    try:
        tuned, r = tune_run(
            model, arrays, fixes=fixes, rest=rest, rest_sigma=rest_sigma, params=params,
            max_evaluations=args.tune_evaluations, max_seconds=args.tune_seconds, announce=announce,
        )  # fmt: skip
    except ValueError as exc:
        raise UserError(f"{args.run}: --tune: {exc}") from None
    figs = ", ".join(f"{f} {r.start[f]:.4g} -> {r.estimate[f]:.4g}" for f in FIGURES)
    stop = "converged" if r.converged else "stopped at its budget: the best figures found, not a maximum"
    verdict = "used" if r.adopted else "not significantly better (p >= 0.05): the model's figures kept"
    unknown = r.unidentified()
    print(
        f"tune: {figs}; ln L +{r.ll_estimate - r.ll_start:.4g} (p = {r.p_value:.3g}); {r.evaluations} evaluations, "
        f"{time.monotonic() - t0[0]:.1f} s, {stop}; {verdict}" + (f"; {unknown}" if unknown else "")
    )
    return tuned


def print_review(review) -> None:
    """The line of the rests' re-examination (pipeline.disagreeing_rests), when it has something to say."""
    if review is not None and review.said:
        print(review.line())


def print_checks(arrays, model: Model, inputs, fixes, smooth_kw, **kw):
    """The checks of the smoothed run (pipeline.smooth_checks, ``kw`` e.g. tuned), a line each; returns them."""
    from accelnav.estimate.pipeline import smooth_checks

    checks = smooth_checks(arrays, model, inputs, fixes, **kw, **smooth_kw)
    for line in checks.lines():
        print(line)
    return checks
