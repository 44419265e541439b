"""Benchmark (issue 24): `accelnav smooth --zupt auto` against the plain command of the same build, two builds.

For each size, runs `smooth NPZ` and `smooth NPZ --zupt auto` as a user does (a subprocess each, data from
bench_smooth_e2e.make_data: the default model's stop-and-go tiled, so rests recur all along) with this
checkout's python and with a baseline checkout's (default /work/main: its own .venv), interleaved, best of
--repeat. Prints wall seconds, peak RSS and the ratio zupt / plain per build: the ratio, not the seconds,
is what holds on a loaded machine, and so do the CPU seconds (user + system) beside them. Also the detector
alone, per build in a process of its own (candidates, then the per-rest decisions; wall and CPU seconds,
best of --repeat by CPU), and how many candidates it decided.
Usage: python bench/run_all.py speed --only bench_zupt_speed, or from bench/speed:
  PYTHONPATH=../common python bench_zupt_speed.py [--sizes 1e6 1e7] [--baseline /work/main] [--keep DIR] [--repeat 1]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from baselines import builds as baseline_builds  # bench/common, on the path bench/run_all.py sets
from bench_smooth_e2e import make_data, run

from accelnav.model.load import load_model

# the detector alone, run by each build's python: argv NPZ, model; prints wall and CPU s of the candidates and
# of the decisions, the candidates' count and the accepted rests' samples
DETECTOR = """
import sys, time
import numpy as np
from accelnav.estimate import zupt
from accelnav.model.load import load_model
m = load_model(sys.argv[2])
accel = np.asarray(np.load(sys.argv[1])["accel"])
clipped = np.zeros(accel.shape, dtype=bool)
p = zupt.resolved(m, zupt.ZuptParams())
t0, c0 = time.perf_counter(), time.process_time()
cand = zupt.candidates(accel, clipped, m, p)
t1, c1 = time.perf_counter(), time.process_time()
decisions = zupt.gate_rests(accel, clipped, cand, m, p)
t2, c2 = time.perf_counter(), time.process_time()
print(t1 - t0, c1 - c0, t2 - t1, c2 - c1, len(decisions), int(zupt.accepted_mask(decisions, len(cand)).sum()))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e6, 1e7])
    ap.add_argument("--baseline", type=Path, default=Path("/work/main"), help="checkout with its own .venv")
    ap.add_argument("--keep", type=Path, default=None, help="keep the data in DIR (default: a temporary folder)")
    ap.add_argument("--repeat", type=int, default=1, help="commands: best of this many")
    args = ap.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="accelnav-bench-zupt-"))
    folder.mkdir(parents=True, exist_ok=True)
    builds = baseline_builds(args.baseline)
    model = load_model(None)
    print(
        "| N | build | plain s | --zupt auto s | ratio | plain CPU s | zupt CPU s | CPU ratio "
        "| plain RSS MB | zupt RSS MB |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    detector = []
    for n in (int(s) for s in args.sizes):
        npz, _, toml = make_data(folder, n, model)
        out = folder / "out.npz"
        best: dict[tuple[str, str], tuple[float, float, float]] = {}
        for _ in range(args.repeat):
            for build, py in builds.items():
                for case, extra in (("plain", []), ("zupt", ["--zupt", "auto"])):
                    argv = [
                        py,
                        "-m",
                        "accelnav.cli",
                        "smooth",
                        str(npz),
                        *extra,
                        "--model",
                        str(toml),
                        "--out",
                        str(out),
                    ]
                    sec, rss, status, err = run(argv, folder)
                    cpu = np.nan
                    if status:
                        print(f"{build} {case} at {n:.0e} failed: {err}")
                    elif err.startswith("CPU "):
                        cpu = float(err.split()[1])
                    old = best.get((build, case), (np.inf, np.nan, np.nan))
                    best[(build, case)] = min(old, (sec, cpu, rss))
                    out.unlink(missing_ok=True)
        for build in builds:
            (tp, cp, rp), (tz, cz, rz) = best[(build, "plain")], best[(build, "zupt")]
            print(
                f"| {n:.0e} | {build} | {tp:.2f} | {tz:.2f} | {tz / tp:.2f} | {cp:.2f} | {cz:.2f} | {cz / cp:.2f} "
                f"| {rp:,.0f} | {rz:,.0f} |"
            )
        sys.stdout.flush()
        alone: dict[str, list[float]] = {}
        for _ in range(args.repeat):
            for build, py in builds.items():
                p = subprocess.run([py, "-c", DETECTOR, str(npz), str(toml)], capture_output=True, text=True)
                if p.returncode:
                    print(f"{build} detector at {n:.0e} failed: {(p.stderr.strip().splitlines() or [''])[-1]}")
                    continue
                got = [float(v) for v in p.stdout.split()]
                if build not in alone or got[1] + got[3] < alone[build][1] + alone[build][3]:
                    alone[build] = got
        detector.extend((n, build, *alone[build]) for build in builds if build in alone)
    print()
    print("Detector alone (each build in a process of its own):")
    print()
    print("| N | build | candidates s | CPU s | decisions s | CPU s | candidates | rest samples |")
    print("|---|---|---|---|---|---|---|---|")
    for n, build, tc, cc, tg, cg, k, r in detector:
        print(f"| {n:.0e} | {build} | {tc:.2f} | {cc:.2f} | {tg:.2f} | {cg:.2f} | {k:,.0f} | {r:,.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
