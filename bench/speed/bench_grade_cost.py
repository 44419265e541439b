"""Benchmark: what a road grade costs a one-axis, gyro-free smoother, given the true rests.

`accelnav sim --scenario stop_and_go` (default model, 120 s, seeds 4-8), with g sin(theta) added to axis
x: theta piecewise linear within +-4 degrees, a knot every 10 s (an ordinary road). Zero-velocity updates
on the true rests (|u| = 0), so the detector is not in question. Three roads:

* flat: no grade;
* grade changing only while stopped: theta held while the car moves (at each rest the bias state
  re-measures it);
* grade changing while moving: the profile as drawn.

Prints the smoothed position rms of axis x per seed and the mean. The difference between the last two
is what the filter cannot know between rests: a grade change while moving reads as acceleration.

Usage: python bench/speed/bench_grade_cost.py [--seeds 5]
"""

from __future__ import annotations

import argparse

import numpy as np

from accelnav.estimate.pipeline import smooth_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.load import G0, load_model

MAX_GRADE_DEG = 4.0
KNOT_S = 10.0


def grade(t: np.ndarray, seed: int, moving: np.ndarray | None) -> np.ndarray:
    """theta [rad]: piecewise linear within +-MAX_GRADE_DEG; held wherever ``moving`` (if given)."""
    knots = np.arange(0.0, t[-1] + KNOT_S, KNOT_S)
    th = np.interp(t, knots, np.radians(np.random.default_rng(seed).uniform(-MAX_GRADE_DEG, MAX_GRADE_DEG, len(knots))))
    if moving is not None:
        held = th.copy()
        for k in np.flatnonzero(moving):
            if k:
                held[k] = held[k - 1]
        th = held
    return th


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
    model = load_model()
    rows = {"flat": [], "grade changing only while stopped": [], "grade changing while moving": []}
    for seed in range(4, 4 + args.seeds):
        run = simulate(model, "stop_and_go", 120.0, seed).to_arrays()
        rest = np.abs(run["u"][:, 0]) < 1e-9
        for name in rows:
            r2 = dict(run)
            if name != "flat":
                th = grade(run["t"], seed, ~rest if "stopped" in name else None)
                r2["accel"] = run["accel"].copy()
                r2["accel"][:, 0] += G0 * np.sin(th)
            out = smooth_run(r2, model, rest=rest)
            rows[name].append(float(np.sqrt(np.mean((out["smooth_x"][0, :, 0] - run["r"][:, 0]) ** 2))))
    print(f"stop_and_go 120 s, seeds 4-{3 + args.seeds}, true rests; smoothed position rms of axis x [m]")
    print("| road | per seed | mean |")
    print("|---|---|---|")
    for name, v in rows.items():
        print(f"| {name} | {' '.join(f'{x:.3f}' for x in v)} | {np.mean(v):.3f} |")


if __name__ == "__main__":
    main()
