"""Run every bench/bench_*.py and collect their markdown tables into one results file.

Each script prints its own markdown (a table, figures beside their baseline
from the same run); this runner adds a heading per script, its command and
wall time, and writes everything to build/bench/results.md (or --out). A
script that fails is recorded with its exit status and the tail of its
stderr, and the runner exits non-zero after writing the file.
Usage: python bench/run_all.py [--out build/bench/results.md] [--only NAME ...]
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE.parent / "build" / "bench" / "results.md")
    ap.add_argument("--only", nargs="*", default=None, help="script names (e.g. bench_fastsmooth) to run")
    args = ap.parse_args()
    scripts = sorted(HERE.glob("bench_*.py"))
    if args.only:
        scripts = [s for s in scripts if s.stem in args.only]
    parts = [
        "# accelnav benchmarks",
        "",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {platform.python_version()}, {platform.machine()}, "
        f"{platform.processor() or platform.platform()}",
        "",
    ]
    failed = 0
    for script in scripts:
        print(f"== {script.name}", flush=True)
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=HERE.parent)
        wall = time.perf_counter() - t0
        sys.stdout.write(done.stdout)
        parts += [f"## {script.stem}", "", f"`python bench/{script.name}` ({wall:.1f} s)", ""]
        if done.returncode == 0:
            parts += [done.stdout.rstrip(), ""]
        else:
            failed += 1
            tail = "\n".join(done.stderr.strip().splitlines()[-8:])
            parts += [f"**failed** (exit status {done.returncode}):", "", "```", tail, "```", ""]
            print(f"   failed with status {done.returncode}", file=sys.stderr)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(parts) + "\n")
    print(f"wrote {args.out}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
