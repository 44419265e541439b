"""Benchmark: what smooth --tune and the model-consistency checks cost per sample, beside the plain smoother.

One run (the default model, scenario vehicle, --minutes long, two axes, a 1 Hz position fix per axis, the
bias walk 30x the model's so that tuning has something to find), one core, best of --repeat:

* smoother, plain path (no aids): the baseline;
* smoother with the fixes (general path), which now also replays the fixes' innovations for their NIS:
  shown with and without that replay (accelnav.estimate.consistency.aid_innovations timed alone);
* the held-out comparison smooth prints with fixes (one more smoothing with half the fixes, two baselines);
* smooth --tune's search (accelnav.estimate.tune.tune, intervals off, the CLI's budget of 300 evaluations
  and 60 s), per sample of the run and per evaluation.

Usage: python bench/speed/bench_tune_cost.py [--minutes 2] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from baselines import best_of  # bench/common, on the path bench/run_all.py sets

from accelnav.cli.core import TUNE_EVALUATIONS, TUNE_SECONDS
from accelnav.estimate import fastsmooth
from accelnav.estimate.consistency import aid_innovations
from accelnav.estimate.kf import position_fix
from accelnav.estimate.pipeline import holdout, smooth_run
from accelnav.estimate.tune import tune
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design
from accelnav.model.edit import with_noise
from accelnav.model.load import load_model


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=2.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    model = load_model()
    truth_model = with_noise(model, sigma_eps=30 * model.noise.sigma_eps)
    run = simulate(truth_model, "vehicle", args.minutes * 60.0, 4).to_arrays()
    n, m = run["accel"].shape
    rng = np.random.default_rng(1)
    step = int(round(model.rate_hz))
    fixes = [
        [position_fix(k, run["r"][k, j] + 0.5 * rng.standard_normal(), 0.5) for k in range(0, n, step)]
        for j in range(m)
    ]
    valid = ~run["clipped"]

    smooth_run(run, model)  # gains cached: the plain path's usual case
    t_plain = best_of(lambda: smooth_run(run, model), args.repeat)
    t_fixes = best_of(lambda: smooth_run(run, model, fixes=fixes), args.repeat)
    res = [
        fastsmooth.smooth(axis_design(model, j), run["accel"][:, j], valid=valid[:, j], extras=fixes[j])
        for j in range(m)
    ]
    P = [fastsmooth.unpack(r.P_prior) for r in res]
    t_nis = best_of(
        lambda: [
            aid_innovations(axis_design(model, j), run["accel"][:, j], valid[:, j], res[j].x_prior, P[j], fixes[j])
            for j in range(m)
        ],
        args.repeat,
    )
    t_hold = best_of(lambda: holdout(run, model, fixes), args.repeat)
    t0 = time.perf_counter()
    r = tune(
        model, run["accel"], valid, fixes, max_evaluations=TUNE_EVALUATIONS, max_seconds=TUNE_SECONDS, intervals=False
    )
    t_tune = time.perf_counter() - t0

    ns = 1e9 / (n * m)
    print(f"vehicle, {args.minutes:g} min, {n} samples x {m} axes, {sum(map(len, fixes))} fixes; best of {args.repeat}")
    print("| stage | ns per sample and axis | x plain smoother |")
    print("|---|---|---|")
    for name, t in (
        ("smoother, plain path (baseline)", t_plain),
        ("smoother with 1 Hz fixes (general path, NIS included)", t_fixes),
        ("  of which the fixes' NIS replay", t_nis),
        ("held-out comparison (smooth with fixes prints it)", t_hold),
        (f"--tune search: {r.evaluations} evaluations, {'converged' if r.converged else 'stopped'}", t_tune),
    ):
        print(f"| {name} | {t * ns:.4g} | {t / t_plain:.3g} |")
    print(f"--tune: {t_tune / r.evaluations * 1e3:.3g} ms per evaluation; sigma_eps {model.noise.sigma_eps:g} -> "
          f"{r.estimate['sigma_eps']:.3g} (truth {truth_model.noise.sigma_eps:g})")  # fmt: skip


if __name__ == "__main__":
    main()
