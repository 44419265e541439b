"""Benchmark: peak memory of the bounded-memory smoother (accelnav.estimate.chunked) against the run's length.

Each case runs in a fresh child process, which reports its wall time and its
peak RSS (VmHWM, this process image's high-water mark), on a two-axis
recording of the default model written as an uncompressed NPZ (generated in
blocks, so the generator is bounded too; deleted afterwards). Rows:

* bounded, library: :class:`chunked.NpzReader` + :func:`chunked.smooth_bounded`
  (input read chunk by chunk from the file, output streamed to an NPZ);
* bounded, CLI: ``accelnav smooth rec.npz --memory-budget 64`` (the CLI reads
  the whole recording into memory first: that part still grows with N);
* whole, CLI: ``accelnav smooth rec.npz`` with an unlimited budget, the
  whole-array path, at the sizes this machine can hold (``--whole``).

Usage: python bench/speed/bench_smooth_bounded.py [--sizes 1e6 1e7] [--whole 3e5 1e6] [--big] [--axes 1|2] [--dir DIR]
(--big adds 1e8: about 50 GB of disk with two axes, 27 GB with --axes 1, for the input, store and output.)
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CHILD = r"""
import sys, time
t0 = time.perf_counter()
kind, rec, out, model_path = sys.argv[1:5]
if kind == "library":
    from accelnav.estimate import chunked
    from accelnav.model.load import load_model
    with chunked.NpzReader(rec) as read:
        info = chunked.smooth_bounded(load_model(model_path), read.n, read, out)
    note = f"{info['chunks']} chunks of {info['chunk']}"
else:
    from accelnav.cli import main
    import contextlib, io
    budget = "64" if kind == "cli-bounded" else "1e9"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["smooth", rec, "--out", out, "--memory-budget", budget, "--model", model_path]) == 0
    note = ""
wall = time.perf_counter() - t0
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:"))
print(f"{wall:.3f} {hwm / 1024:.1f} {note}")
"""


def one_axis_model(path: Path) -> Path:
    """The default model with its x axis only (halves the disk a run needs)."""
    from accelnav.model.load import DEFAULT_MODEL

    text = Path(DEFAULT_MODEL).read_text()
    y = text[text.index('[[axes]]\nname = "y"') : text.index("[noise]")]
    path.write_text(text.replace(y, ""))
    return path


def make_recording(path: Path, n: int, n_axes: int, seed: int = 1, block: int = 1 << 22) -> None:
    """A 100 Hz recording (a slow random walk plus noise, m/s^2) as an uncompressed NPZ."""
    from accelnav.estimate.npzout import NpzWriter

    rng = np.random.default_rng(seed)
    level = np.zeros(n_axes)
    with NpzWriter(path, {"t": ((n,), np.float64), "accel": ((n, n_axes), np.float64)}) as w:
        for s in range(0, n, block):
            e = min(s + block, n)
            walk = level + np.cumsum(rng.normal(0, 1e-3, (e - s, n_axes)), axis=0)
            level = walk[-1]
            w.write("t", s, np.arange(s, e) / 100.0)
            w.write("accel", n_axes * s, walk + rng.normal(0, 0.02, (e - s, n_axes)))


def run(kind: str, rec: Path, out: Path, model: Path) -> tuple[float, float, str]:
    argv = [sys.executable, "-c", CHILD, kind, str(rec), str(out), str(model)]
    done = subprocess.run(argv, capture_output=True, text=True)
    if done.returncode != 0:
        return float("nan"), float("nan"), done.stderr.strip().splitlines()[-1][:80]
    wall, rss, *note = done.stdout.split(maxsplit=2)
    out.unlink(missing_ok=True)
    return float(wall), float(rss), " ".join(note)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="*", default=[1e6, 1e7])
    ap.add_argument("--whole", type=float, nargs="*", default=[3e5, 1e6], help="sizes for the whole-array path")
    ap.add_argument("--big", action="store_true", help="add 1e8 samples")
    ap.add_argument("--axes", type=int, choices=(1, 2), default=2, help="axes of the recording and model")
    ap.add_argument("--dir", type=Path, default=None, help="where the recordings and outputs go; default: a temp dir")
    args = ap.parse_args()
    sizes = sorted({int(n) for n in [*args.sizes, *args.whole, *([1e8] if args.big else [])]})
    work = Path(tempfile.mkdtemp(prefix="bench-bounded-", dir=args.dir))
    from accelnav.model.load import DEFAULT_MODEL

    model = Path(DEFAULT_MODEL) if args.axes == 2 else one_axis_model(work / "x_only.toml")
    print(f"{args.axes} axes, model {model.name}")
    print(f"{'N':>12} {'path':<16} {'wall [s]':>9} {'samples/s':>11} {'peak RSS [MB]':>14}  note")
    try:
        for n in sizes:
            rec = work / "rec.npz"
            t0 = time.perf_counter()
            make_recording(rec, n, args.axes)
            size = f"{rec.stat().st_size / 1e6:.0f} MB"
            print(f"{n:>12} {'(generate)':<16} {time.perf_counter() - t0:9.2f} {'':>11} {'':>14}  {size}")
            kinds = []
            if n in {int(s) for s in args.whole}:
                kinds.append("cli-whole")
            if n in {int(s) for s in args.sizes}:
                kinds += ["cli-bounded", "library"]
            elif n == int(1e8):  # --big: the library alone (the CLI still reads its input whole, GBs at 1e8)
                kinds.append("library")
            for kind in kinds:
                wall, rss, note = run(kind, rec, work / "out.npz", model)
                print(f"{n:>12} {kind:<16} {wall:9.2f} {n / wall:11.3g} {rss:14.0f}  {note}", flush=True)
            rec.unlink()
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
