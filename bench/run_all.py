"""Run one set of bench scripts and collect their markdown into one results file, ending with a targets table.

The sets, one folder each: speed (bench_*.py: time, memory, instruction counts beside a baseline from the
same run), coverage (coverage_*.py: interval coverage over many seeds), studies (study_*.py: design
studies, real recordings). Each script prints its own markdown; this runner adds a heading per script,
its command and wall time, and writes everything to build/bench/<set>.md (or --out). Every markdown
table whose columns include goal, measured and met is gathered, row by row, into one targets table at
the end, so the targets are read in one place. A script that fails is recorded with its exit status and
the tail of its stderr, and the runner exits non-zero after writing the file.

The scripts import the shared baselines (bench/common) and the tests' simulated cases (tests/support)
by module name: this runner puts both folders on their PYTHONPATH, so run a single script through it:

    python bench/run_all.py speed [--out FILE] [--only bench_fastsmooth ...] [--also bench/studies/X.py ...]
    python bench/run_all.py bench/coverage/coverage_tune.py --seeds 0 10     # one script, its own arguments
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent  # bench/: this runner is the one place that knows the checkout's layout
CHECKOUT = HERE.parent
SETS = {"speed": "bench_*.py", "coverage": "coverage_*.py", "studies": "study_*.py"}
TARGET_COLUMNS = ("goal", "measured", "met")


def script_env() -> dict:
    """The environment every script runs in: bench/common and tests/support importable by name."""
    env = dict(os.environ)
    paths = [str(HERE / "common"), str(CHECKOUT / "tests")]
    if env.get("PYTHONPATH"):
        paths.append(env["PYTHONPATH"])
    env["PYTHONPATH"] = os.pathsep.join(paths)
    return env


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def target_rows(script: str, text: str) -> list[tuple[str, str, str, str, str]]:
    """(script, what, goal, measured, met) for each row of each goal | measured | met table in ``text``.

    A column counts by its first word, so "goal (B)" is a goal column whose unit goes with the figures;
    the table's other columns (model, rate, axis, ...) name what the row measures.
    """
    rows = []
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if (
            not line.lstrip().startswith("|")
            or i + 1 >= len(lines)
            or not re.match(r"^\s*\|[\s:|-]+\|\s*$", lines[i + 1])
        ):
            continue
        head = _cells(line)
        first = [h.split()[0].lower() if h else "" for h in head]
        if not all(c in first for c in TARGET_COLUMNS):
            continue
        idx = {c: first.index(c) for c in TARGET_COLUMNS}
        units = {c: head[idx[c]][len(c) :].strip() for c in ("goal", "measured")}
        for body in lines[i + 2 :]:
            if not body.lstrip().startswith("|"):
                break
            cells = _cells(body)
            if len(cells) != len(head):
                break
            named = [(h, v) for h, v, f in zip(head, cells, first, strict=True) if f and f not in TARGET_COLUMNS]
            # one naming column is the name itself; several (model, rate, axis) say which is which
            what = named[0][1] if len(named) == 1 else ", ".join(f"{h} {v}" for h, v in named)
            goal, measured = (f"{cells[idx[c]]} {units[c]}".strip() for c in ("goal", "measured"))
            rows.append((script, what, goal, measured, cells[idx["met"]]))
    return rows


def targets_table(rows) -> list[str]:
    met = sum(r[4].lower().startswith("yes") for r in rows)
    out = ["## Targets", "", f"{met} of {len(rows)} met.", "", "| script | what | goal | measured | met |"]
    out.append("|---|---|---|---|---|")
    out += [f"| {' | '.join(r)} |" for r in rows]
    return out


def run_one(argv: list[str]) -> int:
    """One script with its own arguments, its output straight through."""
    return subprocess.run([sys.executable, *argv], env=script_env(), cwd=CHECKOUT).returncode


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0].endswith(".py"):
        return run_one(argv)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("set", choices=sorted(SETS), nargs="?", default="speed")
    ap.add_argument("--out", type=Path, help="results file (default build/bench/<set>.md)")
    ap.add_argument("--only", nargs="*", default=None, help="script names (e.g. bench_fastsmooth) to run")
    ap.add_argument("--also", nargs="*", type=Path, default=[], help="scripts of other sets to run after these")
    args = ap.parse_args(argv)
    out = args.out or CHECKOUT / "build" / "bench" / f"{args.set}.md"
    scripts = sorted((HERE / args.set).glob(SETS[args.set]))
    if args.only:
        scripts = [s for s in scripts if s.stem in args.only]
    scripts += [s if s.is_absolute() else CHECKOUT / s for s in args.also]
    parts = [
        f"# accelnav benchmarks: {args.set}",
        "",
        f"{time.strftime('%Y-%m-%d %H:%M')}, Python {platform.python_version()}, {platform.machine()}, "
        f"{platform.processor() or platform.platform()}",
        "",
    ]
    failed, targets = 0, []
    for script in scripts:
        rel = script.relative_to(CHECKOUT)
        print(f"== {rel}", flush=True)
        t0 = time.perf_counter()
        done = subprocess.run(
            [sys.executable, str(script)], capture_output=True, text=True, cwd=CHECKOUT, env=script_env()
        )
        wall = time.perf_counter() - t0
        sys.stdout.write(done.stdout)
        parts += [f"## {script.stem}", "", f"`python bench/run_all.py {rel}` ({wall:.1f} s)", ""]
        if done.returncode == 0:
            parts += [done.stdout.rstrip(), ""]
            targets += target_rows(script.stem, done.stdout)
        else:
            failed += 1
            tail = "\n".join(done.stderr.strip().splitlines()[-8:])
            parts += [f"**failed** (exit status {done.returncode}):", "", "```", tail, "```", ""]
            print(f"   failed with status {done.returncode}", file=sys.stderr)
    if targets:
        parts += targets_table(targets) + [""]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(parts) + "\n")
    print(f"wrote {out}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
