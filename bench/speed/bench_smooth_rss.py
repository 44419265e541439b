"""Benchmark: peak RSS of `accelnav smooth` and `accelnav filter` at 1e8 rows, one row per option, same run.

Issue 32's goal: peak RSS <= 1 GB at 1e8 rows for every option. Each option runs once as a user runs it
(a subprocess under GNU time: its wall time, CPU seconds and peak RSS), on one NPZ recording of N rows
(the default model's stop_and_go simulation tiled, as bench_smooth_e2e.py makes it, with its fixes and
rests), written once into --keep DIR (default: a temporary folder, removed after). A row is met only at
N >= 1e8, with the command done (a refusal in one line is the engine keeping its bound, not the option
done within it: it is listed, not met). --before EXE runs each option again with an earlier build right
after, rows marked "(before)".

1e8 rows take 2.4 GB of input and, per option, up to tens of GB of output (--full: every state at
float64; --csv: text): --sizes 3e7 measures the same rows at a size this machine's disk and time allow;
the chunked path's memory is the chunk buffers whatever the length, the whole-array path's grows with it.
Fixes and given rests put their axes on the general path, whose store (14 doubles a sample and axis: 22 GB
at 1e8 with 2 axes) goes to disk beside the output; their aids are made chunk by chunk, so their memory is
the plain path's. --covariances takes the general path on every axis and writes 1 116 B a sample at 2 axes
(chunked.output_bytes): with its store, 137 GB at 1e8, refused up front on a smaller disk; its memory is the
chunk buffers too, so 1e7 measures it.
Usage: python bench/run_all.py bench/speed/bench_smooth_rss.py [--sizes 1e8] [--cases NAME ...]
       [--before EXE] [--keep DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

from bench_smooth_e2e import make_aids, make_data, run

from accelnav.model.load import load_model

GOAL_MB = 1024
GOAL_ROWS = 100_000_000


def cases(npz: Path, fixes: Path, rests: Path, mask: Path, folder: Path) -> dict[str, list]:
    """Every option of smooth and filter that decides the path or the output, as command lines."""
    return {
        "smooth": ["smooth", npz],
        "smooth --full": ["smooth", npz, "--full"],
        "smooth --filter-states": ["smooth", npz, "--filter-states"],
        "smooth --covariances": ["smooth", npz, "--covariances"],
        "smooth --csv": ["smooth", npz, "--csv", folder / "out.csv"],
        "smooth --compress": ["smooth", npz, "--compress"],
        "smooth --fixes": ["smooth", npz, "--fixes", fixes],
        "smooth --zupt MASK (rests given)": ["smooth", npz, "--zupt", mask],
        "smooth --fixes --zupt INTERVALS": ["smooth", npz, "--fixes", fixes, "--zupt", rests],
        "smooth --zupt auto": ["smooth", npz, "--zupt", "auto"],
        "smooth --tune": ["smooth", npz, "--tune"],
        "smooth --plots": ["smooth", npz, "--plots", folder / "plots"],
        "filter": ["filter", npz],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e8])
    ap.add_argument("--cases", nargs="*", default=None, help="only these rows (names as printed)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the data in DIR (default: a temporary folder)")
    ap.add_argument("--python", default=sys.executable, help="interpreter that runs the commands")
    ap.add_argument("--before", default=None, metavar="EXE", help="also run each option with EXE (an earlier build)")
    args = ap.parse_args()
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)  # as an installed package runs (bench_smooth_e2e.py says why)
    model = load_model(None)
    n_axes = len(model.axes)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="accelnav-bench-rss-"))
    folder.mkdir(parents=True, exist_ok=True)
    builds = [("", [args.python, "-m", "accelnav.cli"])]
    if args.before:
        builds.append((" (before)", [args.before, "-m", "accelnav.cli"]))
    print(f"{n_axes} axes; peak RSS of each command under GNU time; the goal is {GOAL_MB} MB at {GOAL_ROWS:.0e} rows.")
    print()
    print("| N | option | s | CPU s | goal | measured | met | note |")
    print("|---|---|---|---|---|---|---|---|")
    try:
        for n in (int(s) for s in args.sizes):
            npz, _, toml = make_data(folder, n, model, with_csv=False)
            fixes, rests, mask = make_aids(folder, n, model)
            out = folder / "out.npz"
            for name, argv in cases(npz, fixes, rests, mask, folder).items():
                if args.cases is not None and name not in args.cases:
                    continue
                for tag, exe in builds:
                    sec, rss, status, note = run([*exe, *map(str, argv), "--model", str(toml), "--out", str(out)],
                                                 folder)  # fmt: skip
                    for f in (out, folder / "out.csv"):
                        f.unlink(missing_ok=True)
                    done = status == 0
                    cpu = note.removeprefix("CPU ").removesuffix(" s") if done else ""
                    met = done and n >= GOAL_ROWS and rss <= GOAL_MB
                    said = note.removeprefix("accelnav: error: ").removeprefix(f"{npz}: ")
                    why = "" if done else f"refused (exit {status}): {said[:110]}"
                    if done and n < GOAL_ROWS:
                        why = f"measured at {n:.0e}, not 1e8"
                    print(f"| {n:.0e} | {name}{tag} | {sec:.1f} | {cpu} | peak RSS <= {GOAL_MB} MB | "
                          f"{rss:,.0f} MB | {'yes' if met else 'no'} | {why} |")  # fmt: skip
                    sys.stdout.flush()
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
