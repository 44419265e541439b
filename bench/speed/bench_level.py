"""Benchmark (issue 35): what levelling costs per sample, beside the plain smoother's, from the same run.

Two tables, each timed in this process, best of --repeat, the rows taken in turn so that a load on the
machine meets them alike:

* **Steps** (--seconds, default 120 s of a foot-like record at 200 Hz: still 0.3 s, then a turn once round an
  axis in 0.7 s, repeated; gravity and noise on the accelerometer, a bias on the gyroscope): the
  gyroscope-aided rest detector (accelnav.level.rests.still_mask), ``level_frame`` with its defaults (rests
  found, bias removed, the gyroscope integrated between them by a prefix scan, the tilt corrected at every
  rest), Fusion's AHRS alone (``passes=0``: its C update called once per sample from Python) and the plain
  smoother on two axes (accelnav.estimate.pipeline.smooth_run, compiled, on the simulated walk of the same
  length). Goal: what accelnav.level adds to the attitude (detector, bias, scan, correction) costs no more
  per sample than the Fusion loop it stands beside.
* **Scale** (--sizes, default N = 1e5 and 1e6 rows of tests/support/hand_moved.py's hand-moved unit, no
  noise): the public ``level_frame(ImuRecord(t, acc, gyro))`` beside the plain smoother (covariances off,
  gains cached by one untimed call, as for a second log of the same sensor) on the levelled x, y, z axes of
  the same rows (models/foot_imu.toml made three-axis with a max_run_s that holds the run), and
  ``accelnav.smooth_run`` (covariances included) for scale. Goal (ours: the issue names none): levelling
  per row at most the plain smoother's (k = 1): both are O(N) compiled passes of a few hundred flops per
  row, so more means a per-sample Python loop.

Usage: python bench/run_all.py bench/speed/bench_level.py [--repeat 3] [--seconds 120] [--sizes 1e5 1e6]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from baselines import best_of  # bench/common, on the path bench/run_all.py sets
from support.hand_moved import hand_moved  # tests/support, on the same path

from accelnav.estimate.pipeline import smooth_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.level import G, ImuRecord, level_frame, rotate
from accelnav.level.rests import still_mask
from accelnav.model.load import load_model
from accelnav.resources import models_dir

RATE = 200.0
K_GOAL = 1.0  # levelling per row <= K_GOAL x the plain smoother's per row


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


def steps_table(args) -> None:
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


def model_for(n: int, folder: Path) -> Path:
    """models/foot_imu.toml with three axes and a max_run_s that holds n rows."""
    from support.realdata_more import model_text

    text = model_text(RATE, ("x", "y", "z"), 10.0, 5000.0)
    run_s = max(3600.0, n / RATE * 1.01)
    old = "max_run_s = 3600.0"
    assert text.count(old) == 1, "models/foot_imu.toml's max_run_s line moved"
    path = folder / f"level_bench_{n}.toml"
    path.write_text(text.replace(old, f"max_run_s = {run_s!r}"))
    return path


def scale_table(args) -> None:
    import accelnav  # the public calls, as a user's notebook makes them

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            n = int(size)
            unit = hand_moved(n, RATE)
            t = unit.t
            imu = ImuRecord(t, unit.acc, unit.gyro)
            out = level_frame(imu)
            model = accelnav.load_model(model_for(n, Path(tmp)))
            cols = {"t": t, "ax": out.acc[:, 0], "ay": out.acc[:, 1], "az": out.acc[:, 2]}
            run, model = accelnav.read_input(cols, model, axes=["ax", "ay", "az"], time_column="t")
            arrays = dict(run)
            smooth_run(arrays, model, covariances=False)  # its gains, cached per model and N, as for a second log
            # in turn, so a load on the machine meets all alike; the best of each
            t_level = t_plain = t_public = np.inf
            for _ in range(args.repeat if n <= 200_000 else 1):
                t_level = min(t_level, best_of(lambda imu=imu: level_frame(imu), 1))
                t_plain = min(t_plain, best_of(lambda a=arrays, m=model: smooth_run(a, m, covariances=False), 1))
                t_public = min(t_public, best_of(lambda r=run, m=model: accelnav.smooth_run(r, m), 1))
            rows.append((n, t_level, t_plain, t_public, out.method))

    print("| N | levelling (us/row) | plain smoother (us/row) | accelnav.smooth_run (us/row) | levelling / plain |")
    print("|---|---|---|---|---|")
    for n, tl, tp, tu, _ in rows:
        print(f"| {n:,} | {tl / n * 1e6:.3f} | {tp / n * 1e6:.3f} | {tu / n * 1e6:.3f} | {tl / tp:.2f} |")
    print()
    print(f"Levelling: {rows[0][4]}; smoothers: 3 axes, no rests.")
    print()
    print("| target | goal | measured | met |")
    print("|---|---|---|---|")
    for n, tl, tp, _, _ in rows:
        ratio = tl / tp
        met = "yes" if ratio <= K_GOAL else "no"
        print(f"| levelling cost per row, N = {n:,} | <= {K_GOAL:g}x the plain smoother's | {ratio:.2f}x | {met} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=120.0)
    ap.add_argument("--sizes", type=float, nargs="+", default=[1e5, 1e6])
    args = ap.parse_args()
    steps_table(args)
    print()
    scale_table(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
