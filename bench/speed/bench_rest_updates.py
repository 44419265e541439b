"""Benchmark (issue 32): a chunk's zero-velocity updates (engine._AxisAids.between), two builds.

`smooth --zupt auto` asks each axis's zero-velocity updates of a chunk twice (forward pass, then again backward):
zupt.RestSpans.updates, then their h, z, R and a Piece's parts (engine._UpdateFill). Rests as the detector gives
them (no sigma of their own), a rest every few seconds over half the run, 2 axes, chunks of 627185 samples (the
1e7-row run's, budget unset). Each build in a process of its own (this checkout's python, and --before EXE's):
each chunk's call timed --repeat times, its best kept, summed over the run's calls. The best of many, not a total:
a call's cost is mostly its fresh pages, and a total swings by a third with the allocator's state and the
machine's load (measured).
Usage: python bench/run_all.py speed --only bench_rest_updates, or from bench/speed:
  python bench_rest_updates.py [--sizes 1e7] [--before EXE] [--repeat 30]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

# run by each build's python: argv N, repeat; prints the calls' best seconds summed and the updates a pass
CHILD = """
import sys, time
import numpy as np
from accelnav.estimate import zupt
from accelnav.estimate.engine import _AxisAids
from accelnav.model.load import load_model

n, repeat, chunk = int(sys.argv[1]), int(sys.argv[2]), 627185
model, p = load_model(None), zupt.ZuptParams()
rng = np.random.default_rng(1)
k = n // 700 + 1
gaps, lens = rng.integers(50, 500, k), rng.integers(50, 800, k)
lo = np.cumsum(gaps + np.concatenate(([0], lens[:-1])))
hi = lo + lens
lo, hi = lo[hi < n], hi[hi < n]
spans = zupt.RestSpans(n, (lo, lo), (hi, hi), (np.full(len(lo), np.nan),) * 2)
aids = [_AxisAids(model, j, zupt.Aids.of([]), spans, p) for j in range(2)]
calls = [(j, s) for j in range(2) for s in range(0, n, chunk)]
best, made = np.full(len(calls), np.inf), 0
for _ in range(repeat):
    for i, (j, s) in enumerate(calls):
        t0 = time.perf_counter()
        piece = aids[j].between(s, min(s + chunk, n))
        best[i] = min(best[i], time.perf_counter() - t0)
        made += len(piece.ex.R)
print(2 * best.sum(), made // repeat)  # asked twice: forward and backward
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e7])
    ap.add_argument("--before", default=None, help="an earlier build's python (its row beside this build's)")
    ap.add_argument("--repeat", type=int, default=30)
    args = ap.parse_args()
    same = args.before is None or Path(args.before).resolve() == Path(sys.executable).resolve()
    if not same and not Path(args.before).exists():
        ap.error(f"--before {args.before}: no such interpreter")
    builds = [("this build", sys.executable)] + ([] if same else [("before", args.before)])
    print("| N | build | updates a pass | s (2 passes, 2 axes, best per call) | goal | met |")
    print("|---|---|---|---|---|---|")
    for n in (int(s) for s in args.sizes):
        got = {}
        for name, exe in builds:  # one after the other, each call best of --repeat
            cmd = [exe, "-c", CHILD, str(n), str(args.repeat)]
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
            if p.returncode != 0:
                print(f"| {n:.0e} | {name} | failed: {(p.stderr.strip().splitlines() or [''])[-1]} | | | |")
                continue
            cpu, made = p.stdout.split()
            got[name] = float(cpu)
            print(f"| {n:.0e} | {name} | {int(made):,} | {float(cpu):.3f} | | |")
        if len(got) == 2:
            met = got["this build"] <= got["before"]
            print(f"| {n:.0e} | this / before | | {got['this build'] / got['before']:.2f}x | <= 1x | {met} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
