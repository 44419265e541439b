"""Benchmark: the float64 reference filter + RTS smoother against FilterPy and pykalman.

Same data, same run: a simulated vehicle recording on the default model, one
axis, N = 1e4 and 1e5 samples. Each library does a full forward filter and
backward smoothing pass. Prints samples/s and our speed relative to each.
Usage: python bench/run_all.py bench/speed/bench_smoother.py [--sizes 10000 100000] [--repeat 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from baselines import filterpy_smooth, pykalman_smooth

from accelnav.estimate.kf import rts_smooth, run_filter
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design
from accelnav.model.load import load_model


def ours(d, z):
    f = run_filter(d, z, progress=False)
    return rts_smooth(d, f, progress=False).x


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
        for name, fn in (("FilterPy", filterpy_smooth), ("pykalman", pykalman_smooth)):
            t, x = timed(fn, d, z, args.repeat)
            diff = np.max(np.abs(x - x_ours) / np.where(sd > 0, sd, 1.0))
            print(f"| {n} | {name} | {t:.3f} | {n / t:,.0f} | {t / t_ours:.2f} | {diff:.1e} |")


if __name__ == "__main__":
    main()
