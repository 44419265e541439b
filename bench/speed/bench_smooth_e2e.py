"""Benchmark: `accelnav smooth` and `accelnav filter` end to end, run as a user runs them, same run.

Each command is a subprocess (start-up, reading, gains, kernel, writing: all of it); its wall time
gives samples/s (rows of the recording, every axis) and GNU time its peak RSS. Beside them, from the
same run and the same data:

* the kernel alone: the plain path's data pass (fastsmooth.plain_data) with its gains cached, every axis;
* FilterPy's batch_filter + rts_smoother on a prefix of --n-baseline rows (it is ~1000x slower:
  subsampled, said in its row), every axis;
* pandas.read_csv of the same CSV, when pandas is installed (it comes with statsmodels' test extras).

Data: the default model's stop_and_go simulation (rests for --zupt auto), tiled to N rows; the model
is the default with ranges.max_run_s raised to the run (the shipped 3600 s is the fixed-point C's
range proof, not a limit of the host tools). Sizes 1e5, 1e6, 1e7 rows; 1e8 only with --big.
Usage: python bench/run_all.py bench/speed/bench_smooth_e2e.py [--sizes 1e5 1e6 1e7] [--big]
       [--n-baseline 20000] [--keep DIR] [--cases "smooth NPZ" ...] [--python EXE]
--python runs the commands with another interpreter (another build of accelnav); --before EXE runs each
command again with EXE (an earlier build) beside it, rows marked "(before)": before and after in one run, the
build that runs first alternating by case and round; --rounds R runs each R times (best time, highest peak).
The kernel-alone row is always this interpreter's. The commands run with their bytecode cached
(PYTHONDONTWRITEBYTECODE is dropped), as an installed package runs: the first command writes it.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from baselines import best_of, filterpy_smooth

from accelnav.estimate import fastsmooth as fs
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design
from accelnav.model.load import DEFAULT_MODEL, MAX_RUN_S, load_model


def make_data(folder: Path, n: int, model, with_csv: bool = True) -> tuple[Path, Path, Path]:
    """(NPZ, CSV, model file) of n rows, written once per size into ``folder`` (the CSV only if asked)."""
    npz, csv, toml = folder / f"rec-{n}.npz", folder / f"rec-{n}.csv", folder / f"model-{n}.toml"
    if not toml.exists():
        # 1 % over the run, within what a model accepts (1e8 rows at 100 Hz are 1e6 s, the bound itself)
        run_s = min(MAX_RUN_S, max(model.ranges.max_run_s, n / model.rate_hz * 1.01))
        text = DEFAULT_MODEL.read_text().replace(f"max_run_s = {model.ranges.max_run_s!r}", f"max_run_s = {run_s!r}")
        assert f"max_run_s = {run_s!r}" in text, "the default model's max_run_s line moved"
        toml.write_text(text)
    if npz.exists() and (csv.exists() or not with_csv):
        return npz, csv, toml
    sim = simulate(model, "stop_and_go", min(model.ranges.max_run_s, n / model.rate_hz), seed=7)
    accel = np.resize(sim.accel, (n, sim.accel.shape[1]))  # tiled: rests recur all along
    t = np.arange(n) / model.rate_hz
    np.savez(npz, t=t, accel=accel, axis_names=np.array([a.name for a in model.axes]))
    if not with_csv:
        return npz, csv, toml
    with open(csv, "w") as fh:
        fh.write("t_s," + ",".join(f"acc_{a.name}_m_s2" for a in model.axes) + "\n")
        step = 1_000_000
        for i in range(0, n, step):
            np.savetxt(fh, np.column_stack((t[i : i + step], accel[i : i + step])), delimiter=",", fmt="%.9g")
    return npz, csv, toml


def make_aids(folder: Path, n: int, model) -> tuple[Path, Path, Path]:
    """(fixes CSV, rest intervals CSV, the same rests as a per-sample mask NPZ) for the n-row data: a fix per
    axis every 60 s, a rest of 1 s every 30 s."""
    fixes, rests, mask = folder / f"fixes-{n}.csv", folder / f"rests-{n}.csv", folder / f"rests-{n}.npz"
    span = (n - 1) / model.rate_hz
    rows = [f"{t:.2f},{a.name},0.0,5.0" for t in np.arange(1.0, span, 60.0) for a in model.axes]
    fixes.write_text("time_s,axis,position_m,sigma_m\n" + "\n".join(rows) + "\n")
    starts = np.arange(5.0, span - 2, 30.0)
    rests.write_text("start_s,end_s\n" + "".join(f"{t:.2f},{t + 1:.2f}\n" for t in starts))
    k = np.round(np.arange(n) / model.rate_hz, 9)
    rest = np.zeros(n, dtype=np.uint8)
    for a in starts:
        rest[np.searchsorted(k, a) : np.searchsorted(k, a + 1, side="right")] = 1
    np.savez(mask, rest=rest)
    return fixes, rests, mask


def make_fleet(folder: Path, count: int, n: int, model) -> list[Path]:
    """``count`` NPZ recordings of n rows each (the stop_and_go simulation, shifted per file)."""
    sim = simulate(model, "stop_and_go", n / model.rate_hz, seed=11)
    accel = np.resize(sim.accel, (n, sim.accel.shape[1]))
    paths = []
    for i in range(count):
        path = folder / f"fleet-{i:03d}.npz"
        if not path.exists():
            np.savez(path, t=np.arange(n) / model.rate_hz, accel=np.roll(accel, 997 * i, axis=0))
        paths.append(path)
    return paths


DOCS = Path(__file__).resolve().parents[2] / "docs" / "python.rst"  # this checkout's docs: the recipe run here


def dask_recipe() -> str:
    """docs/python.rst's Dask block, as printed there (the first python block that maps smooth_batch)."""
    blocks = re.findall(r"\.\. code-block:: python\n\n((?:   .*\n|\n)+)", DOCS.read_text())
    (block,) = [b for b in blocks if "map_partitions(smooth_batch" in b][:1]
    return "\n".join(line[3:] for line in block.splitlines())


def dask_fleet(paths: list[Path], out: Path, workers: int) -> tuple[float, float, float, dict]:
    """(wall s, CPU s of this process, CPU s of the workers, files per worker process) to smooth ``paths``
    through docs/python.rst's Dask block (a bag of smooth_batch over Dask's local processes), run as printed.
    The workers' CPU is counted when Dask's pool has ended them (RUSAGE_CHILDREN, less what it held before)."""
    from collections import Counter

    code = compile(dask_recipe(), str(DOCS), "exec")
    scope = {"paths": paths, "out_dir": out, "options": {}, "workers": workers}
    me0, kids0 = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    t0 = time.perf_counter()
    exec(code, scope)
    sec = time.perf_counter() - t0
    me1, kids1 = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    res = scope["results"]
    assert len(res) == len(paths) and all(r.ok for r in res), [r.message for r in res if not r.ok][:3]
    shutil.rmtree(out)
    cpu = [(b.ru_utime + b.ru_stime) - (a.ru_utime + a.ru_stime) for a, b in ((me0, me1), (kids0, kids1))]
    return sec, cpu[0], cpu[1], Counter(r.pid for r in res)


def run(argv: list[str], folder: Path) -> tuple[float, float, int, str]:
    """(wall s, peak RSS MB, exit status, note) of one command: the note is its last stderr line when it
    failed, else its CPU seconds (user + system: on a machine shared with others' work, the figure that
    wall time hides). The RSS comes from GNU time between us and the command: a child forked from this big
    process would count our pages until exec."""
    rss_file = folder / "rss.txt"
    timer = ["/usr/bin/time", "-q", "-f", "%M %U %S", "-o", str(rss_file)] if Path("/usr/bin/time").exists() else []
    t0 = time.perf_counter()
    p = subprocess.run([*timer, *argv], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    rss, cpu = float("nan"), ""
    if timer:
        fields = rss_file.read_text().split()[-3:]
        rss, cpu = float(fields[0]) / 1024, f"CPU {float(fields[1]) + float(fields[2]):.2f} s"
    return wall, rss, p.returncode, (p.stderr.strip().splitlines() or [""])[-1] if p.returncode else cpu


def write_alone(path: Path, size: int, piece: int = 16 << 20) -> float:
    """Seconds to write ``size`` bytes to a new file in 16 MiB pieces, as the streamed writer does (no
    compute, no fsync): what the output alone costs on this machine, under any command that writes it."""
    buf = np.ones(piece, dtype=np.uint8)
    t0 = time.perf_counter()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        for at in range(0, size, piece):
            os.write(fd, buf[: min(piece, size - at)])
    finally:
        os.close(fd)
    sec = time.perf_counter() - t0
    path.unlink()
    return sec


def kernel_alone(model, accel: np.ndarray, repeat: int) -> float:
    """Seconds of the plain data pass over every axis, gains cached (computed before the timing)."""
    total = 0.0
    for j in range(accel.shape[1]):
        d = axis_design(model, j)
        z = np.ascontiguousarray(accel[:, j])
        g = fs.plain_gains(d, len(z))
        out = (np.empty((len(z), 4)), np.empty((len(z), 4)))
        total += best_of(lambda d=d, z=z, g=g, out=out: fs.plain_data(d, z, None, g, out=out), repeat)
        fs.clear_gain_cache()  # one axis's gains at a time: 300 B per sample
    return total


def cpu_seconds(note: str) -> float:
    """The CPU seconds of a run's note ("CPU 1.23 s"; nan when it failed or GNU time is missing)."""
    return float(note.split()[1]) if note.startswith("CPU ") else float("nan")


def fleet_rows(exe: list[str], folder: Path, count: int, rows: int, model, before: str | None = None,
               rounds: int = 1) -> dict:  # fmt: skip
    """The fleet's rows: ``count`` recordings of ``rows`` rows with --jobs 1 and 2 (and with the build
    ``before``, each right after this one's: the same load on both), the command's start-up (a fleet of one
    file: the serial part, one file's work included), and through Dask (docs/python.rst's block: this build's
    only, it runs in this process). ``rounds`` times each, in turn (which build runs first alternating); a row
    gives the least wall time, with its CPU, and the median. Values: (wall s, CPU s, failed note)."""
    from statistics import median

    got: dict[str, list] = {}
    paths = make_fleet(folder, count, rows, model)
    builds = [("", exe)] + ([(" (before)", [before, "-m", "accelnav.cli"])] if before else [])
    plan = [("start-up", tag, cmd, paths[:1], 1) for tag, cmd in builds]
    for i in range(rounds):
        order = builds if i % 2 == 0 else builds[::-1]
        plan += [(str(jobs), tag, cmd, paths, jobs) for jobs in (1, 2) for tag, cmd in order] + [("dask", "", None,
                 paths, 2)]  # fmt: skip
    for key, tag, cmd, inputs, jobs in plan:
        load = os.getloadavg()[0]
        if key == "dask":
            try:
                sec, parent, workers, split = dask_fleet(paths, folder / "dask-out", jobs)
            except ImportError:
                print("Dask is not installed (pip install 'accelnav[fleet]'): no Dask row")
                continue
            files = "/".join(str(n) for n in sorted(split.values(), reverse=True))
            got.setdefault(key, []).append((sec, parent + workers, float("nan"),
                                            f"CPU {parent:.2f} s here + {workers:.2f} s in the workers, files per "
                                            f"process {files}, load {load:.1f}", parent,
                                            max(split.values()) / count))  # fmt: skip
            continue
        argv = [*cmd, "smooth", *map(str, inputs), "--out-dir", str(folder / "fleet-out"), "--jobs", str(jobs)]
        sec, rss, rc, note = run(argv, folder)
        shutil.rmtree(folder / "fleet-out", ignore_errors=True)
        got.setdefault(key + tag, []).append((sec, cpu_seconds(note), rss, note if rc else f"{note}, load {load:.1f}",
                                              rc))  # fmt: skip
    fleet = {}
    for key, runs in got.items():
        best = min(runs, key=lambda r: r[0])
        failed = [r[3] for r in runs if key != "dask" and r[4]]
        fleet[key] = (best[0], best[1], failed[0] if failed else "")
        if key == "dask":
            fleet["dask serial"], fleet["dask busiest"] = best[4], best[5]
        n_files = 1 if key.startswith("start-up") else count
        what = ("Dask bag, 2 processes (docs/python.rst's block)" if key == "dask" else
                "smooth --out-dir, one file (start-up)" + key[8:] if key.startswith("start-up") else
                f"smooth --out-dir --jobs {key[0]}{key[1:]}")  # fmt: skip
        spread = f"; median of {len(runs)} {median(r[0] for r in runs):.2f} s" if len(runs) > 1 else ""
        rss = "" if best[2] != best[2] else f"{best[2]:,.0f}"
        print(f"| {n_files} x {rows:.0e} | {what} | {best[0]:.2f} | {n_files * rows / best[0]:,.0f} | | | {rss} | "
              f"{best[3][:110]}{spread} |")  # fmt: skip
    return fleet


def two_core_bound(one: float, two: float, serial: float, busiest: float = 0.5) -> float:
    """The speed-up ``one`` / (``serial`` + ``busiest`` * (``two`` - ``serial``)) that CPU seconds allow on 2
    free cores: the serial part on one core, the rest of the 2-process run's CPU shared as it was, ``busiest``
    the share of the process that had the most (a half when shared evenly; no waiting on the disk)."""
    return one / (serial + busiest * (two - serial))


def fleet_targets(line, fleet: dict, count: int, rows: int) -> None:
    """The fleet's targets: the wall ratio of the same run, and beside it the CPU seconds and the bound they
    set on 2 free cores (on a loaded machine the wall ratio says more about the others' work than ours)."""
    for tag in ("", " (before)"):
        if f"1{tag}" not in fleet:
            continue
        (w1, c1, _), (w2, c2, bad), s = fleet[f"1{tag}"], fleet[f"2{tag}"], fleet[f"start-up{tag}"][1]
        r = w1 / w2
        line(f"{count} recordings of {rows:.0e} rows, --jobs 2 >= 1.7x one job{tag}",
             f"{r:.2f}x wall; CPU {c1:.2f} s -> {c2:.2f} s, start-up {s:.2f} s: {two_core_bound(c1, c2, s):.2f}x "
             "on 2 free cores", not bad, r >= 1.7)  # fmt: skip
    if "dask" in fleet and "1" in fleet:
        (w1, c1, _), (wd, cd, _) = fleet["1"], fleet["dask"]
        r = w1 / wd
        busiest = fleet["dask busiest"]
        bound = two_core_bound(c1, cd, fleet["dask serial"], busiest)
        line("the same through Dask (2 processes) >= 1.7x one job",
             f"{r:.2f}x wall; CPU {cd:.2f} s, {100 * busiest:.0f} % of the files in one process: {bound:.2f}x on 2 "
             "free cores", True, r >= 1.7)  # fmt: skip


def read_alone(csv: Path, c_parser: bool) -> float:
    """Seconds for accelnav's CSV reader (recording.csv_pieces, as smooth reads) to parse the file, with
    the C parser (accelnav.data.csvnum) or without it (its numpy path, as where no C module is built)."""
    from accelnav.data import csvnum, recording

    real = csvnum.csv_lib
    csvnum.csv_lib = real if c_parser else (lambda: None)
    try:
        t0 = time.perf_counter()
        for _ in recording.csv_pieces(csv, None, None, None, None, False, "m/s^2"):
            pass
        return time.perf_counter() - t0
    finally:
        csvnum.csv_lib = real


def print_targets(last, fleet: dict, count: int, rows: int, n_axes: int) -> None:
    """The targets table (goal | measured | met) at the largest N, beside its baselines of the same run."""
    n, sec, ok, k_rate, rss, out_bytes = last
    print()
    print(f"Targets at N = {n:.0e} (goal, measured, met):")
    print()
    print("| goal | measured | met |")
    print("|---|---|---|")

    def line(goal, value, met, good):
        print(f"| {goal} | {value} | {'yes' if good and met else 'no'} |")

    def was(name: str, f) -> str:  # the earlier build's figure beside this one's (--before)
        return f" (before: {f(sec[name + ' (before)'])})" if name + " (before)" in sec else ""

    if "smooth NPZ" in sec:
        r = (n / sec["smooth NPZ"]) / k_rate
        before = was("smooth NPZ", lambda s: f"{100 * n / s / k_rate:.1f} %")
        line("smooth from NPZ >= 10 % of the kernel's speed", f"{100 * r:.1f} %{before}", ok["smooth NPZ"], r >= 0.10)
    if "pandas.read_csv of the CSV" in sec and "smooth CSV" in sec:
        r = sec["smooth CSV"] / sec["pandas.read_csv of the CSV"]
        before = was("smooth CSV", lambda s: f"{s / sec['pandas.read_csv of the CSV']:.1f}x")
        line("smooth from CSV within 3x of pandas reading it", f"{r:.1f}x{before}", ok["smooth CSV"], r <= 3)
    if "smooth NPZ --zupt auto" in sec and "smooth NPZ" in sec:
        r = sec["smooth NPZ --zupt auto"] / sec["smooth NPZ"]
        line("--zupt auto within 2x of plain", f"{r:.2f}x", ok["smooth NPZ --zupt auto"], r <= 2)
    if "filter NPZ" in sec:
        r = (n / sec["filter NPZ"]) / k_rate
        before = was("filter NPZ", lambda s: f"{n / s / k_rate:.3f}")
        line("filter >= 1/5 of the smoother kernel's speed", f"{r:.3f}{before}", ok["filter NPZ"], r >= 0.2)
    name = "smooth NPZ --fixes --zupt MASK"
    if name in sec and "smooth NPZ" in sec:
        r = sec[name] / sec["smooth NPZ"]
        line("fixes + rests (given as a mask) within 2x of plain", f"{r:.2f}x", ok[name], r <= 2)
    # the default output of every option that has one (not --full, --filter-states, filter), the aids' NIS with it
    defaults = ("smooth NPZ", "smooth NPZ --zupt auto", "smooth NPZ --fixes --zupt MASK",
                "smooth NPZ --fixes --zupt INTERVALS")  # fmt: skip
    for name in (k for k in defaults if out_bytes.get(k)):
        b = out_bytes[name] / (n * n_axes)
        earlier = out_bytes.get(name + " (before)")
        before = f" (before: {earlier / (n * n_axes):.1f} B)" if earlier else ""
        goal = "default output <= 24 B per sample per axis" + ("" if name == "smooth NPZ" else f": {name}")
        line(goal, f"{b:.1f} B{before}", ok[name], b <= 24)
    for name in (k for k in sec if k.startswith(("smooth ", "filter ")) and not k.endswith("(before)")):
        big = "" if n >= 100_000_000 else f" (measured at {n:.0e}, not 1e8)"
        line(
            f"peak RSS <= 1 GB at 1e8 rows: {name}",
            f"{rss[name]:,.0f} MB{big}",
            ok[name],
            rss[name] <= 1024 and big == "",
        )
    fleet_targets(line, fleet, count, rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e5, 1e6, 1e7])
    ap.add_argument("--big", action="store_true", help="also 1e8 rows (the bounded-memory path)")
    ap.add_argument("--n-baseline", type=int, default=20_000, help="rows FilterPy smooths (it is slow)")
    ap.add_argument("--repeat", type=int, default=3, help="kernel timings: best of this many")
    ap.add_argument("--keep", type=Path, default=None, help="keep the data in DIR (default: a temporary folder)")
    ap.add_argument("--cases", nargs="*", default=None, help="only these command rows (names as printed)")
    ap.add_argument("--python", default=sys.executable, help="interpreter that runs the commands")
    ap.add_argument("--before", default=None, metavar="EXE",
                    help="also run each command with EXE (an earlier build): rows '... (before)'")  # fmt: skip
    ap.add_argument("--rounds", type=int, default=1,
                    help="run each command this many times, builds alternating first: rows give the best")  # fmt: skip
    ap.add_argument("--fleet", type=int, nargs=2, default=[200, 100_000], metavar=("FILES", "ROWS"),
                    help="the fleet rows: FILES recordings of ROWS rows, --jobs 1 and 2 (0 0: none)")  # fmt: skip
    args = ap.parse_args()
    # the commands (and Dask's workers) run as an installed package runs, with its bytecode cached: a shell
    # that forbids writing it (PYTHONDONTWRITEBYTECODE) compiles every module of every command from source,
    # 1.2 s of a 1e7-sample smooth here and as much again in each fleet worker (measured)
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    sys.dont_write_bytecode = False
    sizes = [int(s) for s in args.sizes] + ([100_000_000] if args.big else [])
    model = load_model(None)
    n_axes = len(model.axes)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="accelnav-bench-e2e-"))
    folder.mkdir(parents=True, exist_ok=True)
    exe = [args.python, "-m", "accelnav.cli"]
    try:
        import pandas as pd
    except ImportError:
        pd = None

    # FilterPy once, on a prefix, every axis: rows/s
    sim = simulate(model, "stop_and_go", min(model.ranges.max_run_s, args.n_baseline / model.rate_hz), seed=7)
    zb = np.resize(sim.accel, (args.n_baseline, n_axes))
    t_fp = sum(best_of(lambda j=j: filterpy_smooth(axis_design(model, j), zb[:, j]), 1) for j in range(n_axes))
    fp_rate = args.n_baseline / t_fp

    print(f"{n_axes} axes; samples/s counts rows of the recording (every axis). FilterPy: {args.n_baseline:,} rows "
          f"(subsampled: it is slow), {fp_rate:,.0f} rows/s.")  # fmt: skip
    print()
    print("| N | case | s | samples/s | x kernel | x FilterPy | peak RSS MB | note |")
    print("|---|---|---|---|---|---|---|---|")
    targets = []
    for n in sizes:
        with_csv = args.cases is None or "smooth CSV" in args.cases
        npz, csv, toml = make_data(folder, n, model, with_csv)
        data = np.load(npz)
        t_kernel = kernel_alone(model, np.asarray(data["accel"]), args.repeat)
        del data
        k_rate = n / t_kernel
        results = {"kernel alone (plain data pass, gains cached)": (t_kernel, float("nan"), 0, "")}
        if pd is not None and with_csv:
            t0 = time.perf_counter()
            pd.read_csv(csv)
            results["pandas.read_csv of the CSV"] = (time.perf_counter() - t0, float("nan"), 0, "in process")
        if with_csv:  # the reader alone: what of smooth CSV's time is reading, and what the C parser saves
            for name, c in (("accelnav's CSV reader (C parser)", True), ("accelnav's CSV reader (numpy path)", False)):
                results[name] = (read_alone(csv, c), float("nan"), 0, "in process")
        out = folder / "out.npz"
        fixes, rests, mask = make_aids(folder, n, model)
        cases = {
            "smooth NPZ": ["smooth", npz],
            "smooth CSV": ["smooth", csv],
            "smooth NPZ --zupt auto": ["smooth", npz, "--zupt", "auto"],
            "smooth NPZ --fixes --zupt MASK": ["smooth", npz, "--fixes", fixes, "--zupt", mask],
            # the same rests as 3334 intervals: zupt.read_zupt_file places them by binary search (it painted
            # each interval over every sample: 349 s at 1e7, measured)
            "smooth NPZ --fixes --zupt INTERVALS": ["smooth", npz, "--fixes", fixes, "--zupt", rests],
            "smooth NPZ --filter-states": ["smooth", npz, "--filter-states"],
            "smooth NPZ --full": ["smooth", npz, "--full"],
            "filter NPZ": ["filter", npz],
        }
        if args.cases is not None:
            cases = {k: v for k, v in cases.items() if k in args.cases}
        out_bytes = {}
        # each command with the earlier build beside this one's, the same load on both; which runs first
        # alternates from one case and round to the next (which ran first moved a pair by up to 40 % here)
        builds = [("", exe)] + ([(" (before)", [args.before, "-m", "accelnav.cli"])] if args.before else [])
        runs = [(name + tag, cmd, argv) for c, (name, argv) in enumerate(cases.items()) for i in range(args.rounds)
                for tag, cmd in (builds if (c + i) % 2 == 0 else builds[::-1])]  # fmt: skip
        for name, cmd, argv in runs:
            got = run([*cmd, *map(str, argv), "--model", str(toml), "--out", str(out)], folder)
            was = results.get(name)  # over rounds: the best time with its CPU, the highest peak, any failure
            if was is not None:
                best, bad = min(was, got, key=lambda r: r[0]), was if was[2] else got
                got = (best[0], max(was[1], got[1]), bad[2], bad[3] if bad[2] else best[3])
            results[name] = got
            out_bytes[name] = out.stat().st_size if out.exists() else 0
            out.unlink(missing_ok=True)
        for name, b in out_bytes.items():
            if b:
                print(f"| {n:.0e} | {name}: output | {b / (n * n_axes):.1f} B per sample per axis | | | | | |")
        for name in ("smooth NPZ", "filter NPZ"):
            if out_bytes.get(name):  # the floor under the command: its output's bytes written, nothing computed
                sec = write_alone(folder / "floor.bin", out_bytes[name])
                results[f"writing {name}'s {out_bytes[name] / 1e9:.2f} GB alone"] = (sec, float("nan"), 0, "")
        for name, (sec, rss, _, note) in results.items():
            rate = n / sec
            rss_s = "" if rss != rss else f"{rss:,.0f}"
            print(f"| {n:.0e} | {name} | {sec:.2f} | {rate:,.0f} | {rate / k_rate:.3f} | {rate / fp_rate:,.1f} | "
                  f"{rss_s} | {note[:80]} |")  # fmt: skip
        sec = {k: v[0] for k, v in results.items()}
        ok = {k: v[2] == 0 for k, v in results.items()}
        rss = {k: v[1] for k, v in results.items()}
        targets.append((n, sec, ok, k_rate, rss, out_bytes))
        sys.stdout.flush()

    count, rows = args.fleet
    fleet = fleet_rows(exe, folder, count, rows, model, args.before, args.rounds) if count else {}
    print_targets(targets[-1], fleet, count, rows, n_axes)
    if args.keep is None:
        shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
