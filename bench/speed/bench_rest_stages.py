"""Benchmark: peak RSS and CPU of the `--zupt auto` decision a stage at a time (record, detector, decision), same run.

Issue 32's goal: `smooth --zupt auto` in at most 1 GB at 1e8 rows. The decision reads every sample; this says
which stage holds what, per sample, so the next step moves the largest holder. Each record is decided in a child
process per interpreter (this build, and --before EXE an earlier one, rows marked "(before)"), the peak reset
between stages (/proc/self/clear_refs, VmHWM): "prepare" makes x and ok from the record (streamed, a chunk read
at a time, where the build has zupt._prepared_read; else the record read whole first, held beside the stage but
not in its rise), "detect" the candidates, "decide" the decision on them. "rise" is the stage's peak over the
process' memory when it began, per sample; "CPU s" the stage's user + system seconds (the machine is shared: CPU,
not wall time). Records (2 axes, the default model): the bench's stop-and-go tiled (rests every few seconds), and
one long rest (noise alone: the detector's and the decision's costliest case). The whole decision's row is met
when its peak at 1e8 rows is within the goal; below 1e8 it is listed, not met.
Usage: python bench/run_all.py bench/speed/bench_rest_stages.py [--sizes 1e7] [--before EXE]
"""

from __future__ import annotations

import argparse
import gc
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

GOAL_MB = 1024
GOAL_ROWS = 100_000_000
RECORDS = ("stop_and_go", "one rest")


def _status(key: str) -> float:
    """This process' /proc status figure ``key`` in MB."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f"no {key} in /proc/self/status")


def child(path: Path, n: int) -> None:
    """Decide on the record in ``path`` (n rows of 2 float64), printing a line per stage: name, peak MB, rise MB, the
    process' MB at the start, CPU s."""
    from accelnav.estimate import zupt
    from accelnav.estimate.rests import Clock, decide
    from accelnav.model.design import axis_design
    from accelnav.model.load import load_model

    model = load_model(None)
    n_axes = len(model.axes)

    def read(s: int, e: int):
        a = np.fromfile(path, dtype=np.float64, count=(e - s) * n_axes, offset=s * n_axes * 8).reshape(e - s, n_axes)
        return None, a, np.zeros(a.shape, dtype=bool)

    def stage(name: str, fn):
        gc.collect()
        before = _status("VmRSS")
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")  # the peak (VmHWM) from here
        r0 = resource.getrusage(resource.RUSAGE_SELF)
        out = fn()
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        peak = _status("VmHWM")
        cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
        print(f"{name} {peak:.1f} {peak - before:.1f} {start:.1f} {cpu:.3f}", flush=True)
        return out

    p = zupt.resolved(model, zupt.ZuptParams())
    gc.disable()  # as the decision holds it (zupt.collector_held)
    start = _status("VmRSS")
    if hasattr(zupt, "_prepared_read"):
        x, ok, R = stage("prepare", lambda: zupt._prepared_read(read, n, n_axes, model, 1 << 20))
    else:  # a build before the streamed read: the record whole, not counted in the stage
        _, accel, clipped = read(0, n)
        x, ok, R = stage("prepare", lambda: zupt._prepared(accel, clipped, model))
        del accel, clipped
    rest = stage("detect", lambda: zupt._detect(x, ok, R, model, p))
    sd = max(float(np.sqrt(axis_design(model, j).P0[1, 1])) for j in range(n_axes))
    found = stage("decide", lambda: decide(x, ok, R, model.Ts, Clock(n, model.Ts), zupt.intervals(rest), None, p, sd))
    print(f"decisions {len(found)} {sum(d.accepted for d in found)}", flush=True)


def make_record(path: Path, n: int, record: str) -> None:
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.model.load import load_model

    model = load_model(None)
    if record == "stop_and_go":
        s = simulate(model, "stop_and_go", 200.0, seed=7)
        accel = np.resize(s.accel, (n, s.accel.shape[1]))  # tiled: rests recur all along
    else:
        accel = np.random.default_rng(1).normal(0.0, 0.01, (n, len(model.axes)))
    np.ascontiguousarray(accel, dtype=np.float64).tofile(path)


def measure(exe: str, path: Path, n: int) -> tuple[list[tuple[str, float, float, float]], str]:
    """(stages as (name, peak MB, rise MB, CPU s), decisions note) from a child under ``exe``."""
    p = subprocess.run([exe, __file__, "--child", str(path), str(n)], capture_output=True, text=True)
    if p.returncode:
        raise SystemExit(f"{exe}: the child failed: {(p.stderr.strip().splitlines() or [''])[-1]}")
    rows, note = [], ""
    for line in p.stdout.splitlines():
        f = line.split()
        if f[0] == "decisions":
            note = f"{f[1]} candidates, {f[2]} accepted"
        else:
            rows.append((f[0], float(f[1]), float(f[2]), float(f[4])))
            start = float(f[3])
    peak = max(r[1] for r in rows)
    rows.append(("whole decision", peak, peak - start, sum(r[3] for r in rows)))
    return rows, note


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e7])
    ap.add_argument("--records", nargs="*", default=list(RECORDS), choices=RECORDS)
    ap.add_argument("--before", help="also decide with EXE (an earlier build's python)")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(Path(args.child[0]), int(args.child[1]))
        return 0
    builds = [("", sys.executable)] + ([(" (before)", args.before)] if args.before else [])
    stages, targets = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            n = int(size)
            for record in args.records:
                path = Path(tmp) / "record.f64"
                make_record(path, n, record)
                for mark, exe in builds:
                    rows, note = measure(exe, path, n)
                    for name, peak, rise, cpu in rows:
                        stages.append(f"| {n:.0e} | {record}{mark} | {name} | {peak:,.0f} | {rise:,.0f} | "
                                      f"{rise * 2**20 / n:.1f} | {cpu:.2f} |")  # fmt: skip
                    peak = rows[-1][1]
                    met = "yes" if n >= GOAL_ROWS and peak <= GOAL_MB else "no"
                    where = "" if n >= GOAL_ROWS else f"; measured at {n:.0e}, not 1e8"
                    targets.append(f"| {n:.0e} | {record}{mark} | decision peak RSS <= {GOAL_MB} MB at 1e8 rows | "
                                   f"{peak:,.0f} MB | {met} | {note}{where} |")  # fmt: skip
                path.unlink()
    print("2 axes, the default model; each stage's peak RSS (VmHWM reset at its start) in a child process.\n")
    print("| N | record | stage | peak MB | rise MB | rise B/sample | CPU s |\n|---|---|---|---|---|---|---|")
    print("\n".join(stages))
    print("\n| N | record | goal | measured | met | note |\n|---|---|---|---|---|---|")
    print("\n".join(targets))
    return 0


if __name__ == "__main__":
    sys.exit(main())
