"""Benchmark (issue 35): what levelling costs per sample, beside the plain smoother's, from the same run.

A foot-like record at 200 Hz (still 0.3 s, then a turn once round an axis in 0.7 s, repeated; gravity and
noise on the accelerometer, a bias on the gyroscope), in this process: the gyroscope-aided rest detector
(accelnav.level.rests.still_mask), ``level_frame`` with its defaults (rests found, bias removed, the
gyroscope integrated between them by a prefix scan, the tilt corrected at every rest), Fusion's AHRS alone
(``passes=0``: its C update called once per sample from Python) and the plain smoother on two axes
(accelnav.estimate.pipeline.smooth_run, compiled, on the simulated walk of the same length); best of
--repeat, microseconds per sample. The goal: what accelnav.level adds to the attitude (detector, bias,
scan, correction) costs no more per sample than the Fusion loop it stands beside.

Usage: python bench/run_all.py bench/speed/bench_level.py [--repeat 3] [--seconds 120], or from bench/speed:
  PYTHONPATH=../common python bench_level.py
"""

from __future__ import annotations

import argparse

import numpy as np
from baselines import best_of  # bench/common, on the path bench/run_all.py sets

from accelnav.estimate.pipeline import smooth_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.level import G, ImuRecord, level_frame, rotate
from accelnav.level.rests import still_mask
from accelnav.model.load import load_model
from accelnav.resources import models_dir

RATE = 200.0


def foot_like(seconds: float, seed: int = 1) -> ImuRecord:
    rng = np.random.default_rng(seed)
    ns, nm = int(0.3 * RATE), int(0.7 * RATE)
    cycle = np.r_[np.zeros(ns), np.pi * (1 - np.cos(np.pi * np.arange(nm) / nm))]
    angle = np.tile(cycle, int(np.ceil(seconds / 1.0)))[: int(seconds * RATE)]
    n = angle.size
    t = np.arange(n) / RATE
    half = angle / 2
    q = np.column_stack([np.cos(half), -np.sin(half), np.zeros(n), np.zeros(n)])  # level -> body
    acc = rotate(q, np.tile([0.0, 0.0, G], (n, 1))) + 0.05 * rng.standard_normal((n, 3))
    gyro = np.column_stack([np.gradient(angle, t), np.zeros(n), np.zeros(n)]) + np.radians([0.5, -0.3, 0.2])
    return ImuRecord(t, acc, gyro=gyro + 0.005 * rng.standard_normal((n, 3)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=120.0)
    args = ap.parse_args()
    imu = foot_like(args.seconds)
    n = imu.t.size
    model = load_model(models_dir() / "foot_imu.toml")
    walk = simulate(model, "walking", args.seconds, 1).to_arrays()
    times = {
        "rest detector": best_of(lambda: still_mask(imu.acc, imu.gyro, imu.rate), args.repeat),
        "level_frame, defaults (rests correct)": best_of(lambda: level_frame(imu), args.repeat),
        "Fusion alone (passes=0)": best_of(lambda: level_frame(imu, passes=0), args.repeat),
        "plain smoother, 2 axes": best_of(lambda: smooth_run(walk, model, covariances=False), args.repeat),
    }
    n_walk = len(walk["t"])
    us = {k: 1e6 * v / (n_walk if k.startswith("plain") else n) for k, v in times.items()}
    print(f"| step | µs/sample ({n} samples, {args.seconds:g} s at {RATE:g} Hz) |\n|---|---|")
    for k, v in us.items():
        print(f"| {k} | {v:.3g} |")
    default, fusion = us["level_frame, defaults (rests correct)"], us["Fusion alone (passes=0)"]
    print("\n| goal | measured | met |\n|---|---|---|")
    print(
        f"| level_frame with rests <= Fusion's loop per sample | {default:.3g} against {fusion:.3g} µs/sample "
        f"| {'yes' if default <= fusion else 'NO'} |"
    )
    print(f"| (beside) the plain smoother | {us['plain smoother, 2 axes']:.3g} µs/sample | - |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
