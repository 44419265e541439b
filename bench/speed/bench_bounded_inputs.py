"""Peak memory of the readers on large inputs (issue 21, item 10), beside a baseline build of accelnav.

    python bench/speed/bench_bounded_inputs.py [--csv-rows N] [--log-mib M] [--bomb-mib B] [--baseline DIR]

Each case runs in a fresh child process and reports its peak RSS (ru_maxrss), wall time and the first
line of its outcome. ``--baseline DIR`` is a folder whose ``accelnav`` package is an older build (for
instance ``git archive`` of main's host/ with codegen/ and hil_sim/ linked inside); the same cases run
on it for the baseline column. The inputs are written to a temporary folder and removed afterwards.
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

CHILD = r"""
import resource, sys, time
t0 = time.perf_counter()
try:
    {body}
    out = "ok: " + str(res)
except BaseException as exc:
    out = type(exc).__name__ + ": " + str(exc)
dt = time.perf_counter() - t0
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(f"{{rss:.0f}}\t{{dt:.2f}}\t{{out.splitlines()[0][:90] if out else ''}}")
"""

CASES = {
    "csv": "from accelnav.data.recording import read_recording\n    res = read_recording(sys.argv[1]).n",
    "log info": "from accelnav.data.logs import log_summary\n"
    "    res = log_summary(__import__('pathlib').Path(sys.argv[1]))"
    "['bytes']",
    "npz bomb": "from accelnav.data.recording import read_recording\n    res = read_recording(sys.argv[1]).n",
    "npy header 16 GiB": "from accelnav.data.recording import read_recording\n    res = read_recording(sys.argv[1]).n",
}


def make_csv(path: Path, rows: int) -> None:
    rng = np.random.default_rng(1)
    with open(path, "w") as fh:
        fh.write("t,acc_x_g,acc_y_g\n")
        for k0 in range(0, rows, 100_000):
            k = np.arange(k0, min(rows, k0 + 100_000))
            a = rng.normal(0, 0.01, (len(k), 2))
            np.savetxt(fh, np.column_stack([k / 100.0, a]), fmt=["%.2f", "%.6f", "%.6f"], delimiter=",")


def make_log(path: Path, mib: int) -> None:
    from accelnav.link.logfile import LogWriter
    from accelnav.link.manifest import Manifest
    from accelnav.model.load import load_model

    model = load_model()
    junk = np.random.default_rng(2).integers(0, 256, 1 << 16, dtype=np.uint8).tobytes()
    with LogWriter(path, {"manifest": Manifest.for_model(model).data, "model_toml": model.text}, fsync_s=None) as w:
        for _ in range(mib * 16):
            w.append(junk)
            w.flush()


def make_bomb(path: Path, mib: int) -> None:
    """An NPZ whose 'accel' inflates to ``mib`` MiB of zeros (a few MB on disk)."""
    header = io.BytesIO()
    n = (mib << 20) // 16
    np.lib.format.write_array_header_2_0(header, {"descr": "<f8", "fortran_order": False, "shape": (n, 2)})
    zero = bytes(1 << 22)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        with z.open("accel.npy", "w", force_zip64=True) as fh:
            fh.write(header.getvalue())
            for _ in range((n * 16) // len(zero)):
                fh.write(zero)
        z.writestr("t.npy", _npy(np.arange(4.0)))


def _npy(a) -> bytes:
    b = io.BytesIO()
    np.save(b, a)
    return b.getvalue()


def make_lying_header(path: Path) -> None:
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (1 << 30, 2)})
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("accel.npy", header.getvalue() + bytes(64))


def run(case: str, path: Path, pythonpath: str | None) -> list[str]:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    code = CHILD.format(body=CASES[case])
    r = subprocess.run([sys.executable, "-c", code, str(path)], env=env, capture_output=True, text=True, check=False)
    line = (r.stdout.strip().splitlines() or ["-\t-\t" + (r.stderr.strip().splitlines() or ["?"])[-1][:90]])[-1]
    return line.split("\t")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--csv-rows", type=int, default=3_000_000)
    ap.add_argument("--log-mib", type=int, default=100)
    ap.add_argument("--bomb-mib", type=int, default=1536)
    ap.add_argument("--baseline", type=Path, default=None, help="folder holding an older accelnav package")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        inputs = {
            "csv": tmp / "big.csv",
            "log info": tmp / "big.acnlog",
            "npz bomb": tmp / "bomb.npz",
            "npy header 16 GiB": tmp / "lying.npz",
        }
        make_csv(inputs["csv"], args.csv_rows)
        make_log(inputs["log info"], args.log_mib)
        make_bomb(inputs["npz bomb"], args.bomb_mib)
        make_lying_header(inputs["npy header 16 GiB"])
        print("| case | file MB | build | peak RSS MB | s | outcome |")
        print("|---|---|---|---|---|---|")
        for case, path in inputs.items():
            mb = path.stat().st_size / 1e6
            builds = [("this", None)] + ([("baseline", str(args.baseline))] if args.baseline else [])
            for label, pp in builds:
                rss, dt, out = run(case, path, pp)
                print(f"| {case} | {mb:.1f} | {label} | {rss} | {dt} | {out} |")


if __name__ == "__main__":
    main()
