"""``accelnav demo``: the whole chain on the embedded default model, no hardware needed.

1. A simulated stationary warm-up recording of the sensor (``accelnav sim``).
2. The bias model and noise figures fitted from it (``accelnav fit-bias``).
3. Fixed-point C generated from the fitted model (``accelnav codegen``).
4. A motion scenario run through the firmware built from that C: in-process
   (SIL), and on the emulated Cortex-M3 (PIL) when qemu-system-arm and
   arm-none-eabi-gcc are there, checked bit for bit against SIL.
5. The firmware's telemetry decoded, then filtered and smoothed on the host
   with automatic zero-velocity updates (``accelnav smooth --zupt auto``).
6. A short report in the output folder: the table of position errors and two figures (positions, errors)
   with exactly the table's rows.

The simulator always uses the true sensor (the default model); everything
downstream of the warm-up only knows what fit-bias identified.
"""

from __future__ import annotations

import contextlib
import io
import shutil
import time
from pathlib import Path

from accelnav.data.logs import decoded_run
from accelnav.errors import UserError
from accelnav.fileio import write_text
from accelnav.model.load import DEFAULT_MODEL, load_model

FIX_SIGMA_M = 0.05  # the final position fix's standard deviation: a good fix, as at the end of the paper's walk


def register(sub) -> None:
    p = sub.add_parser("demo", help="the whole chain on the default model: warm-up, fit, codegen, SIL/PIL, smooth")
    p.add_argument("--model", type=Path, default=None, help=f"the true sensor; default: {DEFAULT_MODEL.name}")
    p.add_argument("--scenario", default="stop_and_go", help="motion scenario; default: stop_and_go")
    p.add_argument("--duration", type=float, default=30.0, help="seconds of motion; default: 30")
    p.add_argument("--warmup", type=float, default=1200.0, help="seconds of stationary warm-up; default: 1200")
    p.add_argument("--seed", type=int, default=1, help="random seed; default: 1")
    p.add_argument("--pil", choices=("auto", "on", "off"), default="auto", help="run PIL too; auto: if QEMU is there")
    p.add_argument("--out", type=Path, default=Path("build/demo"), help="output folder; default: build/demo")
    p.set_defaults(func=cmd_demo)


class _Steps:
    """Numbered step lines with their wall time."""

    def __init__(self):
        self.t0 = time.monotonic()
        self.k = 0

    @contextlib.contextmanager
    def step(self, what: str):
        self.k += 1
        t = time.monotonic()
        print(f"[{self.k}] {what} ...", flush=True)
        yield
        print(f"    done in {time.monotonic() - t:.1f} s", flush=True)


def _demo_quiet(argv: list[str], log: Path) -> None:
    """Run an accelnav command with its report going to ``log``; its errors still raise."""
    from accelnav.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        status = main(argv)
    write_text(log, buf.getvalue(), flag="demo log")
    if status != 0:
        raise UserError(f"accelnav {argv[0]} failed (status {status}); see {log}")


def _demo_fit(argv: list[str], log: Path):
    """fit-bias as the command runs it, its report going to ``log``; returns its Characterisation."""
    from accelnav.cli import build_parser
    from accelnav.cli.fit_bias import _fit_bias_run

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        fit = _fit_bias_run(build_parser("fit-bias").parse_args(argv))
    write_text(log, buf.getvalue(), flag="demo log")
    return fit


def _demo_fit_lines(r, true_axis) -> list[str]:
    """An axis's fitted bias beside the truth, each with its 95 % interval; a truth outside it says why."""
    f = r.fit
    names = ("c1", "c2", "T") if f.T_identified else ("c2",)
    lines = [f"    axis {r.name}:" + ("" if f.T_identified else " constant bias (T not identified)")]
    for name in names:
        value, truth, (lo, hi) = getattr(f, name), getattr(true_axis, name), f.interval(name)
        fmt, unit = (".0f", "s") if name == "T" else ("+.4f", "m/s^2")
        line = f"      {name:<2} {value:{fmt}} {unit}, 95 % [{lo:{fmt}}, {hi:{fmt}}], true {truth:{fmt}}"
        why = f.why_truth_outside(name, truth, r.white.white)
        lines.append(line + (f": outside; {why}" if why else ""))
    return lines


def _demo_pil_wanted(mode: str) -> tuple[bool, str]:
    missing = [t for t in ("qemu-system-arm", "arm-none-eabi-gcc") if shutil.which(t) is None]
    if mode == "off":
        return False, "PIL off (--pil off)"
    if missing:
        if mode == "on":
            raise UserError(f"--pil on: {', '.join(missing)} not found")
        return False, f"PIL skipped: {', '.join(missing)} not found"
    return True, ""


def cmd_demo(args) -> int:
    import numpy as np

    from accelnav.data.runfile import save_run
    from accelnav.estimate.kf import position_fix
    from accelnav.estimate.pipeline import dead_reckoning, error_rows, format_errors, smooth_run
    from accelnav.estimate.zupt import rest_mask
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.hil_sim.sim.trajectories import require_scenario
    from accelnav.hil_sim.targets import hil
    from accelnav.hil_sim.targets.firmware import FirmwareError, manifest
    from accelnav.hil_sim.targets.qemu import QemuError
    from accelnav.plots.run import plot_estimates

    true_model = load_model(args.model)
    require_scenario(args.scenario, "--scenario", UserError)
    limit = true_model.ranges.max_run_s
    for name, value in (("--duration", args.duration), ("--warmup", args.warmup)):
        if not 0 < value <= limit:
            raise UserError(f"{name}: got {value:g} s; accepted: seconds in (0, {limit:g}] (model ranges.max_run_s)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    steps = _Steps()
    pil_on, pil_note = _demo_pil_wanted(args.pil)
    print(f"accelnav demo: true sensor {true_model.name}; everything after step 2 knows only the fitted model")

    with steps.step(f"simulate a {args.warmup:g} s stationary warm-up recording"):
        # a characterisation run: the sensor's mean warm-up, without a turn-on draw of the bias
        # (that run-to-run spread is what the motion run below draws and the filter's prior covers)
        warm = simulate(true_model, "stationary", args.warmup, args.seed, initial_random=False)
        save_run(out / "warmup.npz", warm.to_arrays(), true_model)

    with steps.step("fit the bias model and noise figures (accelnav fit-bias)"):
        fitted_path = out / "fitted.toml"
        fit = _demo_fit(
            ["fit-bias", str(out / "warmup.npz"), "--out", str(fitted_path), "--plots", str(out / "fit")],
            out / "fit-bias.txt",
        )
        fitted = load_model(fitted_path)
        for r in fit.axes:
            print("\n".join(_demo_fit_lines(r, true_model.axis(r.name))))
        noise = fitted.noise
        print(f"    R {noise.R:.4g} (m/s^2)^2, sigma_eps {noise.sigma_eps:.3g}; report {out / 'fit-bias.txt'}")

    with steps.step("generate the fixed-point C (accelnav codegen --report)"):
        _demo_quiet(["codegen", str(fitted_path), "--out", str(out / "gen"), "--report"], out / "codegen-report.txt")
        print(f"    {', '.join(sorted(p.name for p in (out / 'gen').iterdir()))}; report {out / 'codegen-report.txt'}")

    with steps.step(f"run {args.duration:g} s of {args.scenario} through the firmware in-process (SIL)"):
        run = simulate(true_model, args.scenario, args.duration, args.seed + 1)
        man = manifest(fitted.source)
        stim = hil.stimulus(man, run)
        sil = hil.run_sil(fitted, stim)
        print(f"    {len(run.t)} samples in, {len(sil)} bytes of telemetry out")

    pil = None
    if pil_on:
        with steps.step("run the same stimulus on the emulated Cortex-M3 (PIL, qemu mps2-an385)"):
            try:
                res = hil.run_pil(fitted, stim, len(run.t), out / "pil.acnlog")
            except (QemuError, FirmwareError) as exc:
                raise UserError(f"PIL: {str(exc).splitlines()[0]}") from None
            pil = res.telemetry
            verdict = "bit-identical to SIL" if pil == sil else "DIFFERS from SIL"
            print(f"    {len(run.t) / res.seconds:,.0f} samples/s; {verdict}")
    else:
        print(f"    ({pil_note})")

    with steps.step("decode the telemetry, filter and smooth with automatic zero-velocity updates"):
        arrays = decoded_run(fitted, run, pil if pil is not None else sil, manifest(fitted.source))
        rest = rest_mask(arrays["accel"], arrays["clipped"], fitted)
        arrays = smooth_run(arrays, fitted, rest=rest)
        # as the paper's Figure 12: one good position arrives at the end; without it the smoother has nothing
        # to smooth toward and its rows equal the firmware filter's
        rng = np.random.default_rng(args.seed + 2)
        k_end = len(run.t) - 1
        end_fix = [
            [position_fix(k_end, float(run.r[k_end, j] + FIX_SIGMA_M * rng.standard_normal()), FIX_SIGMA_M)]
            for j in range(len(run.axis_names))
        ]
        fixed_end = smooth_run(decoded_run(fitted, run, sil, manifest(fitted.source)), fitted, fixes=end_fix)
        save_run(out / "run.npz", arrays, fitted)

    estimates = {  # the table's rows, and the figures' curves: the same dict
        "double integration": dead_reckoning(arrays, fitted)[:, :, 0],
        "firmware filter": arrays["fw_x"][:, :, 0],
        "smoother + final fix": fixed_end["smooth_x"][:, :, 0],
        "smoother + ZUPT": arrays["smooth_x"][:, :, 0],
    }
    rows = error_rows(run.axis_names, run.r, estimates)
    figures = plot_estimates(run.t, run.axis_names, run.r, estimates, out, f"{args.scenario}, seed {args.seed}")
    table = format_errors(rows)
    print()
    print(f"position error against the truth, {args.duration:g} s of {args.scenario} (fitted model, seed {args.seed})")
    print(table)
    lines = [
        "# accelnav demo",
        "",
        f"True sensor `{true_model.name}`; fitted model `{fitted_path.name}`; {args.scenario}, {args.duration:g} s.",
        "",
        table_md(rows),
        "",
        f"The smoother rows have aids the firmware filter does not use: *smoother + final fix* one position "
        f"fix (sigma {FIX_SIGMA_M * 1000:g} mm) at the last sample, as the paper's Figure 12, pulling the whole "
        "track back; *smoother + ZUPT* the zero-velocity updates found by the rest detector.",
        "",
        f"PIL: {'bit-identical to SIL' if pil is not None and pil == sil else pil_note or 'DIFFERS from SIL'}",
        "",
        *[f"![{p.stem}]({p.name})" for p in figures],
    ]
    write_text(out / "report.md", "\n".join(lines) + "\n")  # the output rule, as every file the demo writes
    print()
    print(f"wrote {out / 'report.md'}, figures {', '.join(p.name for p in figures)}, fit figures in {out / 'fit'}")
    print(f"total {time.monotonic() - steps.t0:.1f} s")
    return 0 if pil is None or pil == sil else 1


def table_md(rows) -> str:
    lines = ["| axis | estimate | rms position error [m] | final [m] | max abs [m] |", "|---|---|---|---|---|"]
    lines += [f"| {r.axis} | {r.method} | {r.rms:.3f} | {r.final:.3f} | {r.max_abs:.3f} |" for r in rows]
    return "\n".join(lines)
