"""Benchmark (issue 30): what verifying the cache costs on a warm cache, this build beside a baseline.

Every cache entry is now read whole and its HMAC checked before use (accelnav.cachefile), where the
baseline imported its modules straight from the cache file and mapped the steady gains. Measured in a
fresh process each time (what a user's command pays), warm cache, best of --repeat, this build and a
baseline checkout's (default /work/main: its own .venv), interleaved, each with its own cache folder:

* ``accelnav --version`` (CPU seconds of the process, user + system, as for every command below);
* the SIL firmware module: the generated C (a cached JSON) and the compiled module (about 180 kB), loaded;
* the default model's steady gains of one axis as a run of 6e3 and 3.6e5 samples reads them (the 1.8 MB
  blocks holding its rows) and the whole transient (about 90 MB, 8e5 rows: runs longer than that);
* ``accelnav smooth`` of 60 s, 1400 s and 3600 s simulated runs (CPU s; 6e3, 1.4e5 and 3.6e5 samples;
  3600 s is the longest run the default model declares).

The baseline maps the rows (no copy: about 25 ms however long); reading them costs their page faults
and the HMAC, paid only by runs that need the whole transient (none the default model allows).

Usage: python bench/run_all.py speed --only bench_cache_warm, or from bench/speed:
  PYTHONPATH=../common python bench_cache_warm.py [--baseline /work/main] [--repeat 5] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# the verification's share of a command: at most this much over the baseline (s), or this ratio
# (the rows alone have no goal: a mapped file is free to open, and mapping is what could not stay)
GOALS = {"--version": 1.10, "module": 0.03, "smooth 60 s": 1.10, "smooth 1400 s": 1.15, "smooth 3600 s": 1.15}


def inner(what: str) -> float:
    """One timing in this (fresh) process, s."""
    t0 = time.perf_counter()
    if what == "module":
        from accelnav.hil_sim.targets.firmware import build_firmware

        build_firmware()
    elif what.startswith("rows "):  # the steady rows one axis reads for a run of N samples (all: the whole transient)
        from accelnav.estimate import fastsmooth as fs
        from accelnav.model.design import axis_design
        from accelnav.model.load import load_model

        d = axis_design(load_model(None), 0)
        n = None if what == "rows all" else int(float(what.split()[1]))
        t0 = time.perf_counter()
        st = fs.steady_gains(d, n)
        float(st.rows[:n].sum())  # touch every row the run reads, as its data pass does
    return time.perf_counter() - t0


def timed(py: str, env: dict, args: list[str], cwd: Path) -> float:
    """A command's CPU seconds (user + system: on a machine others load, wall time swings twofold between
    identical runs), or an inner case's own wall time in its process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([py, *args], env=env, cwd=cwd, capture_output=True, text=True, timeout=900)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        raise SystemExit(f"{py} {' '.join(args)}: exit {done.returncode}: {done.stderr[-500:]}")
    if args[0] == __file__:
        return float(done.stdout.strip().splitlines()[-1])
    return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, default=Path("/work/main"), help="checkout with its own .venv")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--keep", type=Path, default=None, help="caches and data in DIR (default: a temporary folder)")
    ap.add_argument("--inner", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.inner:
        print(inner(args.inner))
        return 0
    from baselines import builds as baseline_builds  # bench/common, on the path bench/run_all.py sets

    folder = args.keep or Path(tempfile.mkdtemp(prefix="accelnav-bench-cache-"))
    folder.mkdir(parents=True, exist_ok=True)
    builds = baseline_builds(args.baseline)
    envs = {}
    for b in builds:
        env = {k: v for k, v in os.environ.items() if k != "ACCELNAV_GAIN_CACHE"}
        env.update(ACCELNAV_CACHE_DIR=str(folder / f"cache-{b}"), ACCELNAV_CACHE_KEY_FILE=str(folder / "cache.key"))
        envs[b] = env
    this = builds["this"]
    for secs in (60, 1400, 3600):
        run = folder / f"run{secs}.npz"
        if not run.exists():
            cmd = ["-m", "accelnav", "sim", "--scenario", "stop_and_go", "--duration", str(secs), "--out", str(run)]
            timed(this, envs["this"], cmd, folder)
    cases = {
        "--version": ["-m", "accelnav", "--version"],
        "module": [__file__, "--inner", "module"],
        "rows 6e3": [__file__, "--inner", "rows 6e3"],
        "rows 3.6e5": [__file__, "--inner", "rows 3.6e5"],
        "rows all": [__file__, "--inner", "rows all"],
        "smooth 60 s": ["-m", "accelnav", "smooth", "run60.npz", "--out", "o60.npz"],
        "smooth 1400 s": ["-m", "accelnav", "smooth", "run1400.npz", "--out", "o1400.npz"],
        "smooth 3600 s": ["-m", "accelnav", "smooth", "run3600.npz", "--out", "o3600.npz"],
    }
    best = {b: dict.fromkeys(cases, float("inf")) for b in builds}
    for b, py in builds.items():  # warm each cache first (builds, generates, probes the steady rows)
        for args_ in cases.values():
            timed(py, envs[b], args_, folder)
    for _ in range(args.repeat):
        for name, args_ in cases.items():
            for b, py in builds.items():
                best[b][name] = min(best[b][name], timed(py, envs[b], args_, folder))
    print(f"Warm cache, fresh process each, best of {args.repeat}: commands in CPU s, the rest wall s\n")
    print("| case | " + " | ".join(builds) + " | goal | measured | met |")
    print("|---|" + "---|" * len(builds) + "---|---|---|")
    for name in cases:
        row = " | ".join(f"{best[b][name]:.3f}" for b in builds)
        if "baseline" not in best:
            print(f"| {name} | {row} | - | - | - |")
            continue
        t, base, goal = best["this"][name], best["baseline"][name], GOALS.get(name)
        if goal is None:
            print(f"| {name} | {row} | - | +{t - base:.3f} s | - |")
            continue
        if goal < 1:  # an absolute allowance over the baseline
            measured, met = f"+{t - base:.3f} s", t - base <= goal
            goal_s = f"<= +{goal:.2f} s"
        else:
            measured, met = f"{t / base:.2f}x", t / base <= goal
            goal_s = f"<= {goal:.2f}x baseline"
        print(f"| {name} | {row} | {goal_s} | {measured} | {'yes' if met else 'no'} |")
    sizes = {b: sum(p.stat().st_size for p in (folder / f"cache-{b}").rglob("*") if p.is_file()) for b in builds}
    print("\ncache folder after the runs (MB): " + ", ".join(f"{b} {s / 1e6:.0f}" for b, s in sizes.items()))
    print(json.dumps({b: {k: round(v, 4) for k, v in best[b].items()} for b in builds}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
