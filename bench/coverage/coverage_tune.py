"""Coverage of ``accelnav tune``'s 95 % intervals over seeds (the setting of tests/estimate/test_tune.py).

One axis, data from the filter's own process model (sigma_n 1, sigma_eps 0.01, R 0.016), a position fix
every second, the search started from (3, 0.05, 0.05). Prints, per figure, how many intervals hold the
truth, how many figures were reported identified, and the worst relative error of the estimate.
``--module PATH`` runs another version of accelnav/estimate/tune.py instead (e.g. the one before the
profile-likelihood intervals, ``git show 25ca259:host/estimate/tune.py``).
Usage: python bench/run_all.py bench/coverage/coverage_tune.py [--seeds 0 100] [--samples 6000] [--module PATH]
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

from support.tune_cases import TRUE, one_axis_model, process  # tests/support, on the path bench/run_all.py sets

from accelnav.model.edit import with_noise


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs=2, default=(0, 100), metavar=("FIRST", "END"))
    ap.add_argument("--samples", type=int, default=6000)
    ap.add_argument("--module", type=Path, default=None, help="another tune module (e.g. the previous version)")
    args = ap.parse_args()
    if args.module is None:
        from accelnav.estimate.tune import tune
    else:
        spec = importlib.util.spec_from_file_location("tune_other", args.module)
        mod = importlib.util.module_from_spec(spec)
        sys.modules["tune_other"] = mod  # its dataclasses look their module up
        spec.loader.exec_module(mod)
        tune = mod.tune
    truth = one_axis_model(**TRUE)
    seeds = range(*args.seeds)
    cov = dict.fromkeys(TRUE, 0)
    ident = dict.fromkeys(TRUE, 0)
    worst = dict.fromkeys(TRUE, 0.0)
    misses = []
    evals = []
    t0 = time.perf_counter()
    for seed in seeds:
        z, valid, extras = process(truth, args.samples, seed)
        r = tune(with_noise(truth, sigma_n=3.0, sigma_eps=0.05, R=0.05), z, valid, extras)
        evals.append(r.evaluations)
        for f, v in TRUE.items():
            lo, hi = r.ci95[f]
            covered = bool(lo <= v <= hi)
            cov[f] += covered
            ident[f] += r.identified(f)
            worst[f] = max(worst[f], abs(r.estimate[f] / v - 1))
            if not covered:
                misses.append(f"seed {seed}: {f} {r.estimate[f]:.4g} [{lo:.4g}, {hi:.4g}], truth {v:g}")
    n = len(seeds)
    print(f"{n} seeds ({args.seeds[0]}..{args.seeds[1] - 1}), {args.samples} samples, {args.module or 'accelnav'}")
    print()
    print("| figure | truth in the 95 % interval | identified | worst error of the estimate |")
    print("|---|---|---|---|")
    for f in TRUE:
        print(f"| {f} | {cov[f]}/{n} | {ident[f]}/{n} | {worst[f] * 100:.0f} % |")
    print()
    took = time.perf_counter() - t0
    print(f"likelihood evaluations per run: mean {sum(evals) / n:.0f}, max {max(evals)}; {took:.0f} s")
    for m in misses:
        print(f"  missed: {m}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
