"""Benchmark: reading a big CSV recording, and `accelnav smooth` of it end to end, beside pandas, same run.

Per size: pandas.read_csv of the CSV (in process, the floor of issue 24's 3x target), accelnav's
whole-file reader (read_recording, in process), the streamed reader's first pass (open_stream: parse
into the store and every check), the streamed input alone as a subprocess (open_stream, then every row
read back as the chunked smoother reads them), and `accelnav smooth CSV` as a subprocess, both under
GNU time (wall and peak RSS; over the memory budget the command streams). 1e8 rows (3.5 GB of text, 4 GB
more of disk for the store) only with --big; pandas and the in-process readers run there only with
--big-peers. The command's run file at 1e8 rows needs tens of GB more (chunked.disk_needed): where the
disk lacks them it is refused in one line before reading, and that row says so.

Data: the default model's two axes, noise of 0.3 m/s^2, 100 Hz, written once per size into --keep DIR
(default: a temporary folder, removed afterwards).
Usage: nice python bench/run_all.py bench/speed/bench_big_input.py [--sizes 1e6 1e7] [--big] [--keep DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from accelnav.data.recording import read_recording
from accelnav.data.stream import open_stream
from accelnav.model.load import load_model


def make_csv(folder: Path, n: int, model) -> Path:
    path = folder / f"big-{n}.csv"
    if path.exists():
        return path
    rng = np.random.default_rng(7)
    part = path.with_suffix(".part")
    with open(part, "w") as fh:
        fh.write("t_s," + ",".join(f"acc_{a.name}_m_s2" for a in model.axes) + "\n")
        step = 1_000_000
        for i in range(0, n, step):
            m = min(step, n - i)
            t = np.arange(i, i + m) / model.rate_hz
            np.savetxt(fh, np.column_stack((t, rng.normal(0, 0.3, (m, len(model.axes))))), delimiter=",", fmt="%.9g")
    os.replace(part, path)
    return path


def timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


# the streamed input alone, as the chunked smoother takes it: the first pass, then every row read back
STREAM_ALL = """
import sys
from accelnav.data.stream import open_stream
with open_stream(sys.argv[1], workdir=sys.argv[2]) as st:
    for s in range(0, st.n, 1 << 20):
        st(s, min(s + (1 << 20), st.n))
"""


def smooth(csv: Path, folder: Path) -> tuple[float, float, int, str]:
    """(wall s, peak RSS MB, exit status, last stderr line) of `accelnav smooth` under GNU time."""
    return subprocess_rss([sys.executable, "-m", "accelnav.cli", "smooth", str(csv), "--out", str(folder / "out.npz")],
                          folder)  # fmt: skip


def stream_all(csv: Path, folder: Path) -> tuple[float, float, int, str]:
    """The same for the streamed input alone (no smoother, no output: only the store's disk)."""
    return subprocess_rss([sys.executable, "-c", STREAM_ALL, str(csv), str(folder)], folder)


def subprocess_rss(argv: list[str], folder: Path) -> tuple[float, float, int, str]:
    out, rss_file = folder / "out.npz", folder / "rss.txt"
    timer = ["/usr/bin/time", "-q", "-f", "%M", "-o", str(rss_file)] if Path("/usr/bin/time").exists() else []
    t0 = time.perf_counter()
    p = subprocess.run([*timer, *argv], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    rss = float(rss_file.read_text().split()[-1]) / 1024 if timer else float("nan")
    out.unlink(missing_ok=True)
    return wall, rss, p.returncode, (p.stderr.strip().splitlines() or [""])[-1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="*", type=float, default=[1e6, 1e7])
    ap.add_argument("--big", action="store_true", help="also 1e8 rows")
    ap.add_argument("--big-peers", action="store_true", help="at 1e8 also pandas and the whole reader")
    ap.add_argument("--keep", type=Path, default=None, help="keep the data in DIR")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes] + ([100_000_000] if args.big else [])
    model = load_model(None)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="accelnav-bench-big-"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        import pandas as pd
    except ImportError:
        pd = None
    results: dict[int, dict] = {}
    print("| N | MB of text | case | s | x pandas.read_csv | peak RSS MB | note |")
    print("|---|---|---|---|---|---|---|")
    try:
        for n in sizes:
            csv = make_csv(folder, n, model)
            mb = csv.stat().st_size / 1e6
            peers = n < 100_000_000 or args.big_peers
            rows = {}
            if pd is not None and peers:
                rows["pandas.read_csv"] = (timed(lambda csv=csv: pd.read_csv(csv)), float("nan"), 0, "in process")
            if peers:
                rows["read_recording (whole)"] = (
                    timed(lambda csv=csv: read_recording(csv)),
                    float("nan"),
                    0,
                    "in process",
                )

            def stream_pass(csv=csv):
                with open_stream(csv, model, workdir=folder):
                    pass

            if peers:
                rows["open_stream (parse + checks)"] = (timed(stream_pass), float("nan"), 0, "in process")
            rows["streamed input: open_stream, every row read (subprocess)"] = stream_all(csv, folder)
            rows["accelnav smooth CSV"] = smooth(csv, folder)
            base = rows.get("pandas.read_csv", (float("nan"),))[0]
            for name, (sec, rss, status, err) in rows.items():
                rss_s = "" if rss != rss else f"{rss:,.0f}"
                print(f"| {n:.0e} | {mb:,.0f} | {name} | {sec:.2f} | {sec / base:.2f} | {rss_s} | "
                      f"{(err if status else '')[:90]} |")  # fmt: skip
            sys.stdout.flush()
            results[n] = rows
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)
    targets(results)
    return 0


def targets(results: dict[int, dict]) -> None:
    """Issue 24's input targets: smooth CSV within 3x of pandas reading it (at the largest N pandas read),
    and the 1e8-row CSV in peak RSS <= 2 GB (the command, and the streamed input alone)."""
    print()
    print("| goal | measured | met |")
    print("|---|---|---|")
    timed_n = [n for n, r in results.items() if "pandas.read_csv" in r]
    if timed_n:
        r = results[max(timed_n)]
        sec, _, status, _ = r["accelnav smooth CSV"]
        ratio = sec / r["pandas.read_csv"][0]
        met = "yes" if status == 0 and ratio <= 3 else "no"
        print(f"| smooth of a {max(timed_n):.0e}-row CSV within 3x of pandas.read_csv | {ratio:.2f}x | {met} |")
    for n, r in results.items():
        if n < 100_000_000:
            continue
        for name, (_, rss, status, err) in r.items():
            if rss == rss:
                met = "yes" if status == 0 and rss <= 2048 else "no"
                why = f" (exit {status}: {err[:60]})" if status else ""
                print(f"| {name}, 1e8 rows, peak RSS <= 2 GB | {rss:,.0f} MB{why} | {met} |")


if __name__ == "__main__":
    sys.exit(main())
