"""Benchmark (issue 24): `accelnav smooth --zupt auto` against the plain command of the same build, two builds.

For each size, runs `smooth NPZ` and `smooth NPZ --zupt auto` as a user does (a subprocess each, data from
bench_smooth_e2e.make_data: the default model's stop-and-go tiled, so rests recur all along) with this
checkout's python and with a baseline checkout's (default /work/main: its own .venv), interleaved, best of
--repeat. Prints wall seconds, peak RSS and the ratio zupt / plain per build: the ratio, not the seconds,
is what holds on a loaded machine. Also the detector alone in this process (candidates, then the
per-rest decisions), and how many candidates it decided.
Usage: python bench/run_all.py speed --only bench_zupt_speed, or from bench/speed:
  PYTHONPATH=../common python bench_zupt_speed.py [--sizes 1e6 1e7] [--baseline /work/main] [--keep DIR] [--repeat 1]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from baselines import builds as baseline_builds  # bench/common, on the path bench/run_all.py sets
from bench_smooth_e2e import make_data, run

from accelnav.estimate import zupt
from accelnav.model.load import load_model


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
    print("| N | build | plain s | --zupt auto s | ratio | plain RSS MB | zupt RSS MB |")
    print("|---|---|---|---|---|---|---|")
    detector = []
    for n in (int(s) for s in args.sizes):
        npz, _, toml = make_data(folder, n, model)
        out = folder / "out.npz"
        best: dict[tuple[str, str], tuple[float, float]] = {}
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
                    if status:
                        print(f"{build} {case} at {n:.0e} failed: {err}")
                    old = best.get((build, case), (np.inf, np.nan))
                    best[(build, case)] = min(old, (sec, rss))
                    out.unlink(missing_ok=True)
        for build in builds:
            (tp, rp), (tz, rz) = best[(build, "plain")], best[(build, "zupt")]
            print(f"| {n:.0e} | {build} | {tp:.2f} | {tz:.2f} | {tz / tp:.2f} | {rp:,.0f} | {rz:,.0f} |")
        sys.stdout.flush()
        m = load_model(toml)
        data = np.load(npz)
        accel = np.asarray(data["accel"])
        clipped = np.zeros(accel.shape, dtype=bool)
        p = zupt.resolved(m, zupt.ZuptParams())
        t0 = time.perf_counter()
        cand = zupt.candidates(accel, clipped, m, p)
        t1 = time.perf_counter()
        decisions = zupt.gate_rests(accel, clipped, cand, m, p)
        t2 = time.perf_counter()
        detector.append((n, t1 - t0, t2 - t1, len(decisions), int(zupt.accepted_mask(decisions, n).sum())))
    print()
    print("Detector alone (this build, in process):")
    print()
    print("| N | candidates s | decisions s | candidates | rest samples |")
    print("|---|---|---|---|---|")
    for n, tc, tg, k, r in detector:
        print(f"| {n:.0e} | {tc:.2f} | {tg:.2f} | {k:,} | {r:,} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
