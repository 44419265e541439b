"""The test suite's wall time against the 5-minute budget, and where it goes.

Runs the suite the way CI does (``pytest -q`` with PIL and the real-data
download required, or with what you pass after ``--``) in a child process
with a JUnit report, then prints the wall time beside the budget, the time
per test file, the emulator's share (tests whose name or file says qemu or
pil) against the rest, and the slowest tests.

    .venv/bin/python bench/speed/bench_suite.py [--budget 300] [-- PYTEST ARGS]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=300.0, help="the suite's budget on CI, s")
    ap.add_argument("--top", type=int, default=12, help="slowest tests listed")
    ap.add_argument("pytest_args", nargs="*", help="after --: passed to pytest (default: the whole suite)")
    args = ap.parse_args(argv)
    env = dict(os.environ, ACCELNAV_REQUIRE_PIL="1", ACCELNAV_REQUIRE_REALDATA="1")
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "junit.xml"
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junitxml={report}"]
        t0 = time.perf_counter()
        done = subprocess.run(cmd + args.pytest_args, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if not report.exists():
            print(done.stdout[-2000:], done.stderr[-2000:], sep="\n")
            return 1
        cases = ET.parse(report).getroot().iter("testcase")
        rows = [(c.get("classname", ""), c.get("name", ""), float(c.get("time", 0))) for c in cases]
    print(done.stdout.strip().splitlines()[-1] if done.stdout.strip() else "(no pytest summary)")
    per_file: dict[str, float] = defaultdict(float)
    emu = rest = 0.0
    for cls, name, t in rows:
        per_file[cls.split(".")[1] if "." in cls else cls] += t
        if any(w in (cls + name).lower() for w in ("qemu", "pil")):
            emu += t
        else:
            rest += t
    verdict = "within" if wall <= args.budget else "OVER"
    print(f"suite wall time {wall:.0f} s, {verdict} the {args.budget:.0f} s budget ({wall / args.budget:.0%} of it)")
    print(f"test time: {emu:.0f} s in emulator (PIL/QEMU) tests, {rest:.0f} s in the others, "
          f"{max(wall - emu - rest, 0):.0f} s collection and fixtures outside the tests")  # fmt: skip
    print(f"\n{'file':<36}{'s':>8}")
    for f, t in sorted(per_file.items(), key=lambda kv: -kv[1])[:15]:
        print(f"{f:<36}{t:8.1f}")
    print(f"\n{'slowest tests':<90}{'s':>8}")
    for cls, name, t in sorted(rows, key=lambda r: -r[2])[: args.top]:
        print(f"{(cls.split('.')[-1] + '::' + name)[:88]:<90}{t:8.1f}")
    return done.returncode


if __name__ == "__main__":
    raise SystemExit(main())
