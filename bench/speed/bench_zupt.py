"""Benchmark: the zero-velocity detector's cost beside the smoother's, and the stride-length table of a walk.

1. Cost per sample (one core, two axes, best of --repeat): the detector
   (accelnav.estimate.zupt.candidates, the moving-window tests) and its
   per-rest gate (gate_rests), beside the compiled smoother on the same run,
   plain (no updates) and with the detector's updates (every sample of each
   rest). Runs: stop_and_go (long rests, coasts), walking (a rest per
   second), stop_and_go_graded and highway (issue 23's scenarios), --minutes
   long, default model at 100 Hz. With --old FILE.py (another zupt.py, e.g.
   main's saved aside), its detector + gate on the same run, as a baseline.
2. Walking, --seeds seeds of 60 s, mean absolute stride-length error: the
   smoother with the shipped detector defaults, with the true stance
   intervals (same update settings), without updates, and plain double
   integration; for the default model (100 Hz ADXL250) and the calibrated
   foot IMU (200 Hz).
3. stop_and_go, seeds 101-106 (120 s): smoothed position rms per axis with
   the shipped defaults, beside the figure the previous detector gave on the
   same runs (tests/estimate/test_zupt.py STOP_AND_GO_BEFORE_RMS).

Usage: python bench/speed/bench_zupt.py [--minutes 60] [--seeds 5] [--repeat 3] [--old /tmp/old_zupt.py]
"""

from __future__ import annotations

import argparse

import numpy as np
from baselines import best_of  # bench/common, on the path bench/run_all.py sets

from accelnav.estimate import zupt
from accelnav.estimate.pipeline import dead_reckoning, smooth_run, stride_errors
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.load import load_model
from accelnav.resources import models_dir

# m, the detector before issue #11, same seeds (see tests/estimate/test_zupt.py)
STOP_AND_GO_BEFORE_RMS = (0.1267, 0.1012)


def _module(path: str):
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location("other_zupt", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["other_zupt"] = mod  # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def cost_table(minutes: float, repeat: int, old: str | None = None) -> None:
    model = load_model()
    other = _module(old) if old else None
    print("| run | N | detector ns/sample | gate ns/sample | smoother plain ns/sample | smoother + updates ns/sample "
          "| detector + gate / smoother + updates | --old detector + gate ns/sample |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for scenario in ("stop_and_go", "walking", "stop_and_go_graded", "highway"):
        run = simulate(model, scenario, minutes * 60.0, 3).to_arrays()
        n = len(run["t"])
        acc, clip = run["accel"], run["clipped"]
        cand = zupt.candidates(acc, clip, model)
        t_det = best_of(lambda: zupt.candidates(acc, clip, model), repeat)  # noqa: B023
        t_gate = best_of(lambda: zupt.gate_rests(acc, clip, cand, model), repeat)  # noqa: B023
        rest = zupt.rest_mask(acc, clip, model)
        smooth_run(run, model)  # gains cached: the plain path's usual case
        t_plain = best_of(lambda: smooth_run(run, model), repeat)  # noqa: B023
        t_upd = best_of(lambda: smooth_run(run, model, rest=rest), repeat)  # noqa: B023
        ns = 1e9 / n
        t_old = float("nan")
        if other is not None:
            t_old = best_of(lambda: other.rest_mask(acc, clip, model), repeat)  # noqa: B023
        print(
            f"| {scenario}, {minutes:g} min | {n:,} | {t_det * ns:.0f} | {t_gate * ns:.0f} | {t_plain * ns:.0f} | "
            f"{t_upd * ns:.0f} | {(t_det + t_gate) / t_upd:.2f} | {t_old * ns:.0f} |"
        )
    print()
    print("Per sample of the run (both axes together). The smoother rows include building the run's output arrays.")
    print()


def stride_table(seeds: int) -> None:
    models = [
        ("ADXL250 default, 100 Hz", load_model()),
        ("foot IMU, 200 Hz", load_model(models_dir() / "foot_imu.toml")),
    ]
    print("| model | method | strides | mean abs error [m] | [% of stride] | rms [m] | max [m] |")
    print("|---|---|---|---|---|---|---|")
    for label, model in models:
        per = {}
        for seed in range(1, seeds + 1):
            a = simulate(model, "walking", 60.0, seed).to_arrays()
            rest = zupt.rest_mask(a["accel"], a["clipped"], model)
            est = {
                "smoother, detector defaults": smooth_run(a, model, rest=rest)["smooth_x"][:, :, 0],
                "smoother, true stances": smooth_run(a, model, rest=a["stance"])["smooth_x"][:, :, 0],
                "smoother, no ZUPT": smooth_run(a, model)["smooth_x"][:, :, 0],
                "double integration": dead_reckoning(a, model)[:, :, 0],
            }
            for row in stride_errors(a, est):
                per.setdefault(row.method, []).append(row)
        for method, rows in per.items():
            n = sum(r.n_strides for r in rows)
            mean_abs = sum(r.mean_abs * r.n_strides for r in rows) / n
            length = sum(r.mean_length * r.n_strides for r in rows) / n
            rms = np.sqrt(sum(r.rms**2 * r.n_strides for r in rows) / n)
            mx = max(r.max_abs for r in rows)
            print(
                f"| {label} | {method} | {n} | {mean_abs:.3f} | {100 * mean_abs / length:.1f} | {rms:.3f} | {mx:.3f} |"
            )
    print()
    print(f"Walking scenario, seeds 1-{seeds}, 60 s each; a stride runs from mid-stance to mid-stance.")
    print()


def stop_and_go_table() -> None:
    model = load_model()
    rms = []
    for seed in (101, 102, 103, 104, 105, 106):
        a = simulate(model, "stop_and_go", 120.0, seed).to_arrays()
        out = smooth_run(a, model, rest=zupt.rest_mask(a["accel"], a["clipped"], model))
        e = out["smooth_x"][:, :, 0] - a["r"].T
        rms.append(np.sqrt(np.mean(e**2, axis=1)))
    now = np.mean(rms, axis=0)
    print("| stop_and_go, seeds 101-106, 120 s | axis x rms [m] | axis y rms [m] |")
    print("|---|---|---|")
    print(f"| detector before issue #11 | {STOP_AND_GO_BEFORE_RMS[0]:.4f} | {STOP_AND_GO_BEFORE_RMS[1]:.4f} |")
    print(f"| shipped defaults now | {now[0]:.4f} | {now[1]:.4f} |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--old", default=None, help="another zupt.py whose rest_mask is timed on the same runs")
    args = ap.parse_args()
    cost_table(args.minutes, args.repeat, args.old)
    stride_table(args.seeds)
    stop_and_go_table()


if __name__ == "__main__":
    main()
