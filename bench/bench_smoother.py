"""Benchmark: the float64 reference filter + RTS smoother against FilterPy and pykalman.

Same data, same run: a simulated vehicle recording on the default model, one
axis, N = 1e4 and 1e5 samples. Each library does a full forward filter and
backward smoothing pass. Prints samples/s and our speed relative to each.
Usage: python bench/bench_smoother.py [--sizes 10000 100000] [--repeat 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from codegen.design import axis_design
from codegen.model import load_model
from hil_sim.sensor import simulate
from host.kf import rts_smooth, run_filter


def ours(d, z):
    f = run_filter(d, z, progress=False)
    return rts_smooth(d, f, progress=False).x


def filterpy(d, z):
    from filterpy.kalman import KalmanFilter

    mu = d.eps_mean  # FilterPy's smoother ignores b: run on eps - (c1 + c2)
    kf = KalmanFilter(dim_x=4, dim_z=1)
    kf.x = (d.x0 - [0, 0, 0, mu]).reshape(4, 1)
    kf.P, kf.F, kf.Q, kf.H, kf.R = np.array(d.P0), np.array(d.F), np.array(d.Q), np.array(d.H), np.array([[d.R]])
    xs, Ps, _, _ = kf.batch_filter((z - mu).reshape(-1, 1), update_first=True)
    x, _, _, _ = kf.rts_smoother(xs, Ps)
    return x.reshape(-1, 4) + [0, 0, 0, mu]


def pykalman(d, z):
    from pykalman import KalmanFilter

    kf = KalmanFilter(
        transition_matrices=np.array(d.F),
        observation_matrices=np.array(d.H),
        transition_covariance=np.array(d.Q),
        observation_covariance=np.array([[d.R]]),
        transition_offsets=np.array(d.b),
        observation_offsets=np.zeros(1),
        initial_state_mean=np.array(d.x0),
        initial_state_covariance=np.array(d.P0),
    )
    return kf.smooth(z.reshape(-1, 1))[0]


def timed(fn, d, z, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn(d, z)
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()

    model = load_model()
    d = axis_design(model, 0)
    run = simulate(model, "vehicle", max(args.sizes) * model.Ts, seed=7)
    print("| N | implementation | seconds | samples/s | ours is x faster | max |diff| / sigma vs ours |")
    print("|---|---|---|---|---|---|")
    for n in args.sizes:
        z = run.accel[:n, 0]
        t_ours, x_ours = timed(ours, d, z, args.repeat)
        sd = np.sqrt(np.einsum("kii->ki", rts_smooth(d, run_filter(d, z, progress=False), progress=False).P))
        print(f"| {n} | accelnav reference | {t_ours:.3f} | {n / t_ours:,.0f} | 1.00 | 0 |")
        for name, fn in (("FilterPy", filterpy), ("pykalman", pykalman)):
            t, x = timed(fn, d, z, args.repeat)
            diff = np.max(np.abs(x - x_ours) / np.where(sd > 0, sd, 1.0))
            print(f"| {n} | {name} | {t:.3f} | {n / t:,.0f} | {t / t_ours:.2f} | {diff:.1e} |")


if __name__ == "__main__":
    main()
