"""Benchmark: position error on the rest-detection scenarios (issue 23), the detector against a perfect one.

Per scenario and seed: the smoother with the detector's defaults (accelnav.estimate.zupt.rest_mask), with
the true rests as the mask, and with no zero-velocity update; optionally with another detector module
(--old FILE.py, e.g. main's host/estimate/zupt.py saved aside) on the same runs. Figures: position error
of the horizontal vector (all axes), rms over the run and at its end, m, mean over the seeds; rests
accepted / true rests.

Usage: python bench/speed/bench_rest_scenarios.py [--seeds 3] [--duration 60] [--old /tmp/old_zupt.py]
"""

from __future__ import annotations

import argparse
import importlib.util
import sys

import numpy as np
from support.cart_model import adxl335_model  # tests/support, on the path bench/run_all.py sets

from accelnav.estimate import zupt
from accelnav.estimate.pipeline import smooth_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.load import load_model
from accelnav.resources import models_dir

CASES = [  # (scenario, model)
    ("stop_and_go", "default"),
    ("vehicle", "default"),
    ("walking", "default"),
    ("walking", "foot"),
    ("walking_drift", "default"),
    ("walking_drift", "foot"),
    ("walking_fast", "foot"),
    ("stop_and_go_graded", "default"),
    ("highway", "default"),
    ("cart_push", "adxl335"),
]


def models():
    return {"default": load_model(None), "foot": load_model(models_dir() / "foot_imu.toml"), "adxl335": adxl335_model()}


def errors(out, arrays) -> tuple[float, float]:
    e = np.linalg.norm(out["smooth_x"][:, :, 0].T - arrays["r"], axis=1)
    return float(np.sqrt(np.mean(e**2))), float(e[-1])


def true_rest(arrays) -> np.ndarray:
    if "rest" in arrays:
        return arrays["rest"]
    if "stance" in arrays:
        return arrays["stance"]
    return np.all(arrays["u"] == 0, axis=1)


def evaluate(scenario, model, seed, duration, detectors) -> dict[str, tuple[float, float, int]]:
    arrays = simulate(model, scenario, duration, seed).to_arrays()
    truth = true_rest(arrays)
    masks = {name: det(arrays["accel"], arrays["clipped"], model) for name, det in detectors.items()}
    masks["true rests"] = truth
    masks["no ZUPT"] = None
    out = {}
    for name, mask in masks.items():
        res = smooth_run(arrays, model, rest=mask)
        n = len(zupt.intervals(mask)) if mask is not None else 0
        out[name] = (*errors(res, arrays), n)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--old", default=None, help="another zupt.py to compare (its rest_mask)")
    args = ap.parse_args()
    detectors = {}
    if args.old:
        spec = importlib.util.spec_from_file_location("old_zupt", args.old)
        old = importlib.util.module_from_spec(spec)
        sys.modules["old_zupt"] = old  # dataclasses look their module up there
        spec.loader.exec_module(old)
        detectors["defaults (old)"] = old.rest_mask
    detectors["defaults"] = zupt.rest_mask
    ms = models()
    names = [*detectors, "true rests", "no ZUPT"]
    print(f"{args.seeds} seeds x {args.duration:g} s; position error |r - r_true| over all axes, m: rms / final "
          "(rests accepted)")  # fmt: skip
    print("| scenario | model | " + " | ".join(names) + " |")
    print("|---|---|" + "---|" * len(names))
    for scenario, mname in CASES:
        rows = [evaluate(scenario, ms[mname], seed, args.duration, detectors) for seed in range(1, args.seeds + 1)]
        cells = []
        for name in names:
            rms = np.mean([r[name][0] for r in rows])
            fin = np.mean([r[name][1] for r in rows])
            n = np.mean([r[name][2] for r in rows])
            cells.append(f"{rms:.3g} / {fin:.3g} ({n:.0f})")
        print(f"| {scenario} | {mname} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
