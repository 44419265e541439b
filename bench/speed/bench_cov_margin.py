"""Precision margin of the fixed-point filters (the covariance form, or --form gain_schedule) against the
float64 Kalman filter.

For every shipped scenario (accelnav.hil_sim.sim.trajectories.SCENARIOS), a few seeds and every axis of the
model, the generated C runs in-process (cffi) beside the float64 filter with the same skips
(rail-clipped samples); the figure is the largest |x_C - x_float64| / sigma_float64 over the samples
after the first second, per state, and the margin is the 1e-3 sigma criterion divided by it.

    .venv/bin/python bench/speed/bench_cov_margin.py [MODEL.toml] [--rate HZ] [--duration S] [--seeds 11 9 3]
        [--form covariance|gain_schedule] [--baseline PYTHON]

--baseline runs this same script under another interpreter (e.g. /work/main/.venv/bin/python, whose
editable install is main's generator) and prints its figures beside this one's, measured in the same run.

Issue #12, c_r, c_v, c_a in fine formats away from gaps (codegen.ranges._plan_fine), default model at
1 kHz, seeds 11 9 3, against the generator before it in the same run: smallest margin 8.1x (3.7x);
shock r, u, a 3.6e-5, 6.1e-5, 1.08e-4 sigma (2.65e-4, 2.32e-4, 2.68e-4), eps unchanged at 1.23e-4,
now the largest. Seeds 1 2 4 5 6 7 8 10 12 13: 4.9x (stress, eps 2.06e-4, the same before: c_e keeps
the format its initial value sets); shock 5.9x. At 100 Hz (--rate 100 --duration 10) 16.7x (11.0x).
adxl202_duty at 100 Hz: 3.0x (2.8x), a on shock at 3.4e-4, a limit this change does not touch.
Then c_e in a fine format too (away from gaps, from its settling on), against main 0b32d51 in the same run
(--baseline): 1 kHz, seeds 1..13: 9.3x (4.9x), stress eps 3.0e-5 sigma (2.06e-4), shock 9.3x (5.9x) now
held by a at 1.08e-4; 100 Hz, --duration 10, seeds 11 9 3: 22.5x (16.7x); adxl202_duty at 100 Hz,
--duration 3, seeds 11 9 3: 5.6x (5.5x), a at 1.8e-4.

The gain schedule (--form gain_schedule; its criterion is 1e-3 sigma itself), seeds 1..13, against main
2ef5af7 in the same run (--baseline): 100 Hz, --duration 10: 2.2x (0.5x: shock r 1.6e-3, u 2.1e-3 sigma on
seeds 2 and 13), now held by a at 4.5e-4 on shock and stress; 1 kHz, --duration 3: 1.5x (0.8x: shock r
1.3e-3 on seed 5), a at 6.8e-4 on shock; adxl202_duty at 100 Hz, --duration 10: 3.6x (2.0x). The change:
codegen.follow's return to the schedule at the schedule's own tolerance of each sample, its deviation
entries zoomed as they decay, and K_a's tolerance 1e-7 (2e-7).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CRITERION = 1e-3
STATES = ("r", "u", "a", "eps")


def measure(model_path, rate, duration, seeds, workdir, form="covariance") -> dict:
    from accelnav.codegen.emit_c import emit
    from accelnav.estimate.kf import run_filter
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.hil_sim.sim.trajectories import SCENARIOS
    from accelnav.hil_sim.targets.harness import AxisRunner, build
    from accelnav.model.design import axis_design
    from accelnav.model.load import load_model, loads_model

    model = load_model(model_path)
    if rate is not None and rate != model.rate_hz:
        text = model.text.replace(f"rate_hz = {model.rate_hz!r}", f"rate_hz = {rate!r}")
        model = loads_model(text, source=f"{model.source}@{rate:g}Hz")
        assert model.rate_hz == rate, "rate_hz not found in the model text"
    files = emit(model, form=form)
    mod = build(files, workdir)
    k1 = int(model.rate_hz)
    out = {}
    for sc in SCENARIOS:
        worst = np.zeros(4)
        clipped = 0
        overflow = 0
        for seed in seeds:
            run = simulate(model, sc, duration, seed=seed)
            for axis in range(len(model.axes)):
                valid = ~run.clipped[:, axis]
                clipped += int((~valid).sum())
                ref = run_filter(axis_design(model, axis), run.accel[:, axis], valid=valid, progress=False)
                sig = np.sqrt(np.einsum("kii->ki", ref.P_post))
                if model.sensor.kind == "analog":
                    res = AxisRunner(mod, files["accelnav.json"], axis).run(code=run.code[:, axis])
                else:
                    res = AxisRunner(mod, files["accelnav.json"], axis).run(t1=run.t1[:, axis], t2=run.t2[:, axis])
                overflow += res["overflow"]
                worst = np.maximum(worst, (np.abs(res["x"] - ref.x_post)[k1:] / sig[k1:]).max(0))
        out[sc] = {"sigma": worst.tolist(), "clipped": clipped, "overflow": overflow}
    return {"model": model.name, "rate": model.rate_hz, "scenarios": out}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=None)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=[11, 9, 3])
    ap.add_argument("--form", default="covariance", choices=("covariance", "gain_schedule"))
    ap.add_argument("--baseline", help="a Python whose accelnav is the generator to compare with")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # one process's raw figures
    args = ap.parse_args(argv)
    from accelnav.codegen.ranges import RangeError
    from accelnav.model.load import ModelError

    try:
        with tempfile.TemporaryDirectory(prefix="acn_margin_") as tmp:
            now = measure(args.model, args.rate, args.duration, args.seeds, Path(tmp), args.form)
    except (ModelError, RangeError, OSError) as e:  # a model this generator refuses or cannot read
        raise SystemExit(f"bench_cov_margin: {str(e).splitlines()[0]}") from None
    if args.json:
        print(json.dumps(now))
        return 0
    base = None
    if args.baseline:
        model = [str(Path(args.model).resolve())] if args.model else []  # the child runs in another folder
        cmd = [args.baseline, __file__, *model, "--json", "--rate", str(args.rate)]
        cmd += ["--duration", str(args.duration), "--form", args.form, "--seeds", *map(str, args.seeds)]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, cwd=tempfile.gettempdir())
        if done.returncode:
            raise SystemExit(f"baseline failed: {done.stderr.strip().splitlines()[-1:]}")
        base = json.loads(done.stdout)
    print(
        f"model {now['model']}, {args.form} form, {now['rate']:g} Hz, {args.duration:g} s, seeds {args.seeds}, "
        f"every axis: max |x_C - x_float64| / sigma after 1 s (criterion {CRITERION:g}; margin = criterion / "
        "worst state)"
    )
    head = f"{'scenario':<12} {'clipped':>7} " + " ".join(f"{s:>8}" for s in STATES) + f" {'margin':>7}"
    print(head + (f"   {'baseline: ' + ' '.join(f'{s:>8}' for s in STATES)} {'margin':>7}" if base else ""))
    for sc, v in now["scenarios"].items():
        row = f"{sc:<12} {v['clipped']:7d} " + " ".join(f"{x:8.2e}" for x in v["sigma"])
        row += f" {CRITERION / max(v['sigma']):6.1f}x"
        if base:
            b = base["scenarios"][sc]
            row += "   " + " " * 10 + " ".join(f"{x:8.2e}" for x in b["sigma"])
            row += f" {CRITERION / max(b['sigma']):6.1f}x"
        if v["overflow"]:
            row += f"  overflow {v['overflow']}"
        print(row)
    worst = min(CRITERION / max(v["sigma"]) for v in now["scenarios"].values())
    if args.form == "covariance":  # issue #12: the covariance form at >= 5x
        line = f"smallest margin: {worst:.1f}x (target >= 5x: {'met' if worst >= 5 else 'NOT met'})"
    else:  # the gain schedule: within the criterion itself
        line = f"smallest margin: {worst:.1f}x (within {CRITERION:g} sigma: {'met' if worst >= 1 else 'NOT met'})"
    if base:
        line += f"; baseline {min(CRITERION / max(v['sigma']) for v in base['scenarios'].values()):.1f}x"
    print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
