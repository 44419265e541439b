"""Benchmark: the compiled filter + RTS smoother (host/estimate/fastsmooth.py) against FilterPy, same run.

One axis of the default model, one core. Rows:

* plain path, data pass: forward filter and RTS smoother of all four states,
  with the gains already cached for this model and N (the common case: many
  logs of one sensor). Then cold: computing the gains and covariances too.
* general path: the full 4-state filter and smoother with measurements that
  vary in time; warm reuses its output buffers, cold allocates them (at
  N = 1e6 that is 336 MB, and first-touch page faults cost a good share).
* FilterPy batch_filter + rts_smoother and the accelnav reference (host/estimate/kf.py)
  at a smaller N (they are 1000x slower), same data prefix.

Agreement: max over samples and states of |ours - ref| / (|ref| + sigma)
against the reference at N = 4000. Usage: python bench/run_all.py bench/speed/bench_fastsmooth.py
[--n 1000000] [--n-baseline 20000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from baselines import best_of, filterpy_smooth

from accelnav.estimate import fastsmooth as fs
from accelnav.estimate import zupt
from accelnav.estimate.kf import rts_smooth, run_filter
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design
from accelnav.model.load import load_model


def rel_err(x, x_ref, P_ref) -> float:
    sd = np.sqrt(np.einsum("kii->ki", P_ref))
    err = np.abs(x - x_ref)
    bound = np.abs(x_ref) + sd
    return float(np.max(np.where(err == 0, 0.0, err / np.where(bound > 0, bound, np.inf))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--n-baseline", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    n, nb = args.n, args.n_baseline

    model = load_model()
    d = axis_design(model, 0)
    # the model allows runs of max_run_s; longer inputs repeat a simulated stop-and-go run
    sim = simulate(model, "stop_and_go", min(model.ranges.max_run_s, n * model.Ts), seed=7)
    z = np.resize(sim.accel[:, 0], n)
    rest = zupt.rest_mask(sim.accel, sim.clipped, model)
    ks = zupt.update_samples(rest, model)
    reps = -(-n // len(sim.t))
    ks_all = np.concatenate([ks + i * len(sim.t) for i in range(reps)])
    ks_all = ks_all[ks_all < n]
    extras, gates = zupt.measurements(ks_all)

    rows = []

    def row(path, what, N, seconds, agree=""):
        rows.append((path, what, N, seconds, N / seconds, agree))

    # agreement with the reference at a size it can do
    na = 4000
    f = run_filter(d, z[:na])
    s = rts_smooth(d, f)
    agree_plain = rel_err(fs.smooth_plain(d, z[:na]).xs, s.x, s.P)
    ex_a = [m for m in extras if m.k < na]
    fa = run_filter(d, z[:na], extras=ex_a)
    sa = rts_smooth(d, fa)
    agree_general = rel_err(fs.smooth_general(d, z[:na], extras=ex_a).xs, sa.x, sa.P)

    fs.clear_gain_cache()
    t0 = time.perf_counter()
    g = fs.plain_gains(d, n)
    t_gains = time.perf_counter() - t0
    out = (np.empty((n, 4)), np.empty((n, 4)))
    t_data = best_of(lambda: fs.plain_data(d, z, None, g, out=out), args.repeat)
    row("plain", "data pass, gains cached", n, t_data, f"{agree_plain:.1e}")
    row("plain", "cold: gains + covariances + data", n, t_gains + t_data, f"{agree_plain:.1e}")
    buf = fs.smooth_general(d, z)
    t_gen = best_of(lambda: fs.smooth_general(d, z, out=buf), max(2, args.repeat // 2))
    row("general", "no extras, buffers reused", n, t_gen, "")
    t_genz = best_of(lambda: fs.smooth_general(d, z, extras=extras, gates=gates, out=buf), max(2, args.repeat // 2))
    row("general", f"{len(extras)} gated ZUPTs, buffers reused", n, t_genz, f"{agree_general:.1e}")
    buf = None  # free the 336 MB before the fresh-buffer timing
    t_genc = best_of(lambda: fs.smooth_general(d, z, extras=extras, gates=gates), 2)
    row("general", f"{len(extras)} gated ZUPTs, fresh buffers", n, t_genc, f"{agree_general:.1e}")

    t_fp = best_of(lambda: filterpy_smooth(d, z[:nb]), 1)
    row("FilterPy", "batch_filter + rts_smoother", nb, t_fp, "")
    t_ref = best_of(lambda: rts_smooth(d, run_filter(d, z[:nb], progress=False), progress=False), 1)
    row("reference", "host/estimate/kf.py run_filter + rts_smooth", nb, t_ref, "0")

    fp_rate = nb / t_fp
    print("| path | what | N | seconds | samples/s | x FilterPy | max err / (abs(ref) + sigma) |")
    print("|---|---|---|---|---|---|---|")
    for path, what, N, sec, rate, agree in rows:
        print(f"| {path} | {what} | {N:,} | {sec:.4f} | {rate:,.0f} | {rate / fp_rate:,.0f} | {agree} |")
    print()
    print(
        f"Targets: plain >= 5e7 samples/s and >= 1000x FilterPy at N = 1e6 (measured {n / t_data:.2e}, "
        f"{(n / t_data) / fp_rate:,.0f}x); general >= 2e6 samples/s (measured {n / t_genz:.2e} with ZUPTs, "
        f"{n / t_genc:.2e} with fresh buffers); agreement <= 1e-9."
    )


if __name__ == "__main__":
    main()
