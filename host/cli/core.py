"""``accelnav sim``, ``filter`` and ``smooth``: the simulate -> filter -> smooth chain on run files."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from accelnav.api import simulate
from accelnav.cli.args import clock_args, reader_options
from accelnav.data.inputs import read_input
from accelnav.data.runfile import STATE, export_csv, save_run, state_sd
from accelnav.errors import UserError
from accelnav.estimate.pipeline import (
    format_errors,
    format_strides,
    position_errors,
    stride_table,
    truth_versus_baselines,
)
from accelnav.estimate.zupt import ZuptParams
from accelnav.fileio import check_output, write_text
from accelnav.model.load import DEFAULT_MODEL, Model, load_model

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
    p.add_argument(
        "--full",
        action="store_true",
        help="write every state (r, u, a, eps) and its sd at float64 and echo the input (accel, clipped, raw counts, "
        "truth): the run file accelnav-run/2, about 77 B per sample per axis, which accelnav smooth reads again; "
        "default: r, u and their sd at float32 beside t, 20 B per sample per axis at 2 axes (accelnav-run/3)",
    )
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
    p.add_argument("run", type=Path, nargs="+", help=INPUT_HELP + "; several with --out-dir (a fleet)")
    _model_arg(p, "; default: the model embedded in the input, else the embedded default")
    _input_args(p)
    p.add_argument("--out", type=Path, default=None, help="run file to write (.npz); one input")
    p.add_argument(
        "--out-dir",
        type=Path,
        default=None,
        metavar="DIR",
        help="a run file per input, DIR/<input name>.npz: many recordings in one command; a file that fails is "
        "reported and the others finish (exit status 1 if any failed)",
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        metavar="N",
        help="with --out-dir: smooth N inputs at a time in worker processes (the memory budget shared); default 1",
    )
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
        help=f"--tune: wall time of the search at most (the best figures by then are used; a run whose evaluations "
        f"this cuts short is told so first); default {TUNE_SECONDS:g}",
    )
    p.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write PNG plots into DIR")
    p.add_argument(
        "--filter-states",
        action="store_true",
        help="also write the forward filter's states filt_x, filt_sd when the run streams (by default it writes "
        "the smoother's alone: the filter's doubled the file and its writing time; accelnav filter writes "
        "them, and so do --covariances, --plots and runs that keep every sample in memory (aids within the "
        "budget, ...))",
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
        help="memory the run may take; a longer run is smoothed in chunks (its store in memory within the budget, "
        "without one within 1 GiB, else on disk beside --out; of the aids' consistency checks only their NIS); "
        "--covariances are written chunk by chunk (the general path: 544 B per sample and axis); --tune reads "
        "the input again for every likelihood evaluation; --plots draws from each series' min and max per "
        "pixel column, kept while the chunks are written; default: half "
        "the memory free",
    )
    p.add_argument(
        "--full",
        action="store_true",
        help="write every state (r, u, a, eps) and its sd at float64 and echo the input (accel, clipped, raw counts, "
        "truth): the run file accelnav-run/2, about 77 B per sample per axis; default: r, u and their sd at float32 "
        "beside t, 20 B per sample per axis at 2 axes (accelnav-run/3)",
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


def _job_options(args, **kw):
    """The engine's Job from the command's flags."""
    from accelnav.estimate.engine import Job

    return Job(
        covariances=args.covariances,
        full=args.full,
        budget=_memory_budget_arg(getattr(args, "memory_budget", None)),
        **kw,
    )


def _read_options(args) -> dict:
    return dict(allow_gaps=args.allow_gaps, **reader_options(args))


def _print_run(args, outcome) -> None:
    """The summary of a filtered or smoothed run, then how it was cut and where it went."""
    from accelnav.data.smoothing import summary_arrays

    arrays, n = summary_arrays(outcome)
    print(_summary(arrays, n))
    if outcome.arrays is not None:
        rows = position_errors(arrays, outcome.model)
        if rows:
            print(format_errors(rows))
            line = truth_versus_baselines(rows, outcome.checks is not None and outcome.checks.tune_helps)
            if "smooth_x" in arrays and line:
                print(line)
        strides = stride_table(arrays, outcome.model) if "smooth_x" in arrays else []
        if strides:
            print(format_strides(strides))
    else:
        p = outcome.plan
        store = "in memory" if outcome.store_in_memory else f"on disk beside {args.out}"
        src = f"; the input streamed from the {outcome.streamed} a chunk at a time" if outcome.streamed else ""
        verb = "smoothed" if "smooth_x" in outcome.ends else "filtered"
        print(f"{args.run}: {verb} in bounded memory, streamed: {p.why}, the store {store}{src}")
    for path in outcome.written:
        print(f"wrote {path}")


def cmd_filter(args) -> int:
    from accelnav.data.smoothing import smooth_file

    outcome = smooth_file(args.run, args.out, args.model, job=_job_options(args, stages=("filt",)), csv=args.csv,
                          compress=args.compress, **_read_options(args))  # fmt: skip
    _print_run(args, outcome)
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
    from accelnav.data.smoothing import smooth_file
    from accelnav.estimate.engine import Tune

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
    from accelnav.estimate.tune import FIGURES

    tune = None
    if args.tune:
        if args.tune_evaluations < 10:
            raise UserError(f"--tune-evaluations: got {args.tune_evaluations}; accepted: 10 or more")
        if not args.tune_seconds > 0:
            raise UserError(f"--tune-seconds: got {args.tune_seconds:g}; accepted: a time > 0 s")

        def announce(n: int, m: int, aids: int) -> None:
            print(
                f"tune: fitting {', '.join(FIGURES)} to {n} samples x {m} axes with {aids} aids; budget "
                f"{args.tune_evaluations} evaluations, {args.tune_seconds:g} s"
            )

        tune = Tune(args.tune_evaluations, args.tune_seconds, announce)
    stages = ("filt", "smooth") if args.filter_states else ("smooth",)
    if args.out_dir is not None or len(args.run) > 1:
        return _smooth_fleet(args, params, stages)
    if args.out is None:
        raise UserError("--out: a run file to write is required (or --out-dir DIR for several inputs)")
    args.run = args.run[0]
    job = _job_options(args, stages=stages, tune=tune, warm_start=args.warm_start,
               envelope=args.plots is not None)  # fmt: skip
    outcome = smooth_file(
        args.run, args.out, args.model, job=job, fixes=args.fixes, zupt=args.zupt, zupt_params=params,
        zupt_report=args.zupt_report, csv=args.csv, compress=args.compress, rests_decided=_print_rests,
        **_read_options(args),
    )  # fmt: skip
    if outcome.tune is not None:
        _print_tune(outcome.tune, outcome.model)
    if outcome.applied is not None:
        print(f"zero-velocity updates applied per axis: {', '.join(map(str, outcome.applied))}")
    if outcome.fixes is not None:
        print(f"position fixes per axis: {', '.join(map(str, outcome.fixes))}")
    if outcome.checks is not None:
        for line in outcome.checks.lines():
            print(line)
    _print_run(args, outcome)
    if args.plots is not None:
        from accelnav.plots.run import plot_outcome

        for path in plot_outcome(outcome, args.plots):
            print(f"wrote {path}")
    return 0


def _smooth_fleet(args, params: ZuptParams, stages: tuple[str, ...]) -> int:
    """smooth over many inputs (accelnav.data.smoothing.smooth_files): a line per input as it finishes."""
    from accelnav.data.smoothing import smooth_files

    if args.out_dir is None:
        raise UserError(f"{len(args.run)} inputs: give --out-dir DIR (a run file per input), not --out")
    single = [f for f, v in (("--out", args.out), ("--csv", args.csv), ("--plots", args.plots),
                             ("--zupt-report", args.zupt_report), ("--fixes", args.fixes), ("--tune", args.tune))
              if v]  # fmt: skip
    if args.zupt not in (None, "auto"):
        single.append("--zupt FILE")
    if single:
        raise UserError(f"--out-dir: {', '.join(single)} belong(s) to one input; accepted with a fleet: --zupt auto")
    job = _job_options(args, stages=stages, warm_start=args.warm_start)

    def done(r) -> None:
        print(f"{'ok' if r.ok else 'FAILED'} {r.path}: {r.message}" + (f" -> {r.out}" if r.ok else ""), flush=True)

    results = smooth_files(
        args.run, args.out_dir, jobs=args.jobs, done=done, model=args.model, job=job, zupt=args.zupt,
        zupt_params=params, compress=args.compress, **_read_options(args),
    )  # fmt: skip
    failed = [r for r in results if not r.ok]
    print(f"{len(results) - len(failed)} of {len(results)} inputs smoothed into {args.out_dir}"
          + (f"; {len(failed)} failed: {', '.join(r.path for r in failed)}" if failed else ""))  # fmt: skip
    return 1 if failed else 0


def _memory_budget_arg(mb: float | None) -> int | None:
    if mb is None:
        return None  # the engine's default
    if not mb > 0:
        raise UserError(f"--memory-budget: got {mb:g}; accepted: megabytes > 0")
    return int(mb * (1 << 20))


def _print_tune(tuned, model: Model) -> None:
    """smooth --tune's line: the figures found, the likelihood gained, the search's cost, the verdict."""
    from accelnav.estimate.tune import FIGURES

    r, seconds = tuned
    figs = ", ".join(f"{f} {r.start[f]:.4g} -> {r.estimate[f]:.4g}" for f in FIGURES)
    stop = "converged" if r.converged else "stopped at its budget: the best figures found, not a maximum"
    verdict = "used" if r.adopted else "not significantly better (p >= 0.05): the model's figures kept"
    unknown = r.unidentified()
    print(
        f"tune: {figs}; ln L +{r.ll_estimate - r.ll_start:.4g} (p = {r.p_value:.3g}); {r.evaluations} evaluations, "
        f"{seconds:.1f} s, {stop}; {verdict}" + (f"; {unknown}" if unknown else "")
    )


def _print_rests(r) -> None:
    """The rest stage's lines (an engine.RestOutcome), printed as it is decided: the decision's summary, then
    its review (the rests dropped, before --tune and any advice)."""
    if not r.detected:
        return
    print(_zupt_summary(r.decisions, r.params, r.mask, r.gravity))
    if not r.reviewed:
        print(
            "rests not re-examined against a smoother with the fixes and the other rests: the run is over the "
            "memory budget of the whole-array path (--memory-budget)"
        )
    print_review(r.review)


def print_review(review) -> None:
    """The line of the rests' re-examination (pipeline.disagreeing_rests), when it has something to say."""
    if review is not None and review.said:
        print(review.line())
