"""Codegen time and peak memory against the declared run length, beside the previous generator.

For each model (the default ADXL250 at 100 Hz for 1 h, at 1 kHz with three axes for 1 h, at 10 kHz for
the longest run accepted, and at 100 kHz for 30 min, which the validator accepts), ``emit`` + the
``--report`` text run in a child process, timed, with the child's peak RSS (getrusage). The same child
runs the generator of BASE_COMMIT (extracted from git into a temporary package; the issue #12 "before")
under an address-space cap, so a run that would take the machine's memory is reported as such.

    .venv/bin/python bench/speed/bench_codegen_cost.py [--base COMMIT] [--cap-mb MB] [--form gain_schedule]
                                                 [--no-cc] [--case TEXT ...]

``--no-cc``: both children run with no C compiler reachable (CC=false, an empty cache folder of their
own), as a user of the wheel without gcc: "now" takes the kernel compiled into the package, a
generator without one its Python twins; each cell says which ([C] or [Python]). ``--case TEXT``: only
the models whose name contains TEXT (repeatable).

Gain-schedule form, issue #12 (the schedule's search and the report's bound), one run of
`--form gain_schedule --base c6b42e5` (main before it) on the shared 2-core machine; seconds with the
report (without it), peak RSS:

| model | c6b42e5 | now |
|---|---|---|
| 100 Hz, 2 axes, 1 h | 7.96 s (1.99 s), 170 MB | 2.02 s (0.60 s), 102 MB |
| 1 kHz, 2 axes, 1 h | 66.75 s (16.91 s), 172 MB | 5.80 s (2.49 s), 150 MB |
| 1 kHz, 3 axes, 1 h | 70.54 s (16.48 s), 185 MB | 7.87 s (3.59 s), 168 MB |
| 10 kHz, 2 axes, 839 s | 112.03 s (33.70 s), 179 MB | 9.72 s (3.21 s), 152 MB |

No C compiler reachable, the kernels compiled into the package (covariance form; `--no-cc --base main`
with main before the kernels went into the wheel, where the gain recursion then ran in Python; its
1 kHz row re-run with a 6000 MB cap, the default 1500 MB one ends in MemoryError after 207 s):

| model | main, no compiler | now, no compiler |
|---|---|---|
| 100 Hz, 2 axes, 1 h | 19.87 s (10.94 s), 359 MB | 0.80 s (0.35 s), 59 MB |
| 1 kHz, 3 axes, 1 h | 346.53 s (194.93 s), 3295 MB | 1.62 s (0.85 s), 72 MB |
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

from accelnav.resources import models_dir

BASE_COMMIT = "3cab69e"  # main before issue #12

CHILD = r"""
import importlib, json, resource, sys, time
cap = int(sys.argv[2])
if cap:
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
pkg = sys.argv[1]
text = sys.stdin.read()
out = {}
t0 = time.perf_counter()
try:
    m = importlib.import_module(pkg + ".model")
    e = importlib.import_module(pkg + ".emit_c")
    r = importlib.import_module(pkg + ".report")
    t0 = time.perf_counter()
    model = m.loads_model(text, source="bench.toml")
    files = e.emit(model)
    out["emit_s"] = time.perf_counter() - t0
    r.report(model, form=None, arith="fixed", files=files, prefix="accelnav")
    out["ok"] = True
    lib = getattr(importlib.import_module(pkg + ".gains"), "_riccati_lib", lambda: None)
    out["kernel"] = "C" if lib() else "Python"
except MemoryError:
    out["error"] = "MemoryError at the cap"
except ValueError as exc:  # ModelError: a refusal
    out["refused"] = str(exc).split(": ", 1)[-1][:90]
out["seconds"] = time.perf_counter() - t0
out["rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
try:  # VmHWM: this process image's high-water mark (ru_maxrss carries a forked parent's over exec)
    out["rss_mb"] = [int(ln.split()[1]) for ln in open("/proc/self/status") if ln.startswith("VmHWM:")][0] / 1024
except (OSError, IndexError):
    pass
print(json.dumps(out))
"""

Z_AXIS = '[[axes]]\nname = "z"\nc1 = 0.03\nc2 = -0.02\nT = 200.0\n\n[noise]'


def model_text(rate: float, run_s: float, three_axes: bool = False, form: str = "covariance") -> str:
    text = (models_dir() / "adxl250_default.toml").read_text()
    text = text.replace("rate_hz = 100.0", f"rate_hz = {rate:.1f}").replace(
        "max_run_s = 3600.0", f"max_run_s = {run_s!r}"
    )
    text = text.replace('form = "covariance" ', f'form = "{form}" ')
    return text.replace("[noise]", Z_AXIS, 1) if three_axes else text


def _checkout() -> str:
    """The git work tree holding this script (the base commit's codegen comes from its history)."""
    here = Path(__file__).resolve().parent
    done = subprocess.run(["git", "-C", str(here), "rev-parse", "--show-toplevel"], check=True, capture_output=True)
    return done.stdout.decode().strip()


def extract_base(commit: str, dest: Path) -> str:
    """The codegen package of ``commit`` as the importable package ``acn_base_codegen`` under dest."""
    tar = subprocess.run(["git", "-C", str(_checkout()), "archive", commit, "codegen"], check=True, capture_output=True)
    with tarfile.open(fileobj=BytesIO(tar.stdout)) as tf:
        tf.extractall(dest, filter="data")
    (dest / "codegen").rename(dest / "acn_base_codegen")
    return "acn_base_codegen"


def run_child(pkg: str, text: str, cap_mb: int, path: Path | None, timeout: float = 300.0, no_cc=False) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "ACCELNAV_PURE_PYTHON"}
    if path is not None:
        env["PYTHONPATH"] = str(path) + os.pathsep + env.get("PYTHONPATH", "")
    with tempfile.TemporaryDirectory(prefix="acn_cache_") as cache:
        if no_cc:  # no compiler, and no module a compiler built earlier (the builder reuses its cache)
            env.update(CC="false", ACCELNAV_CACHE_DIR=cache)
        return _child(pkg, text, cap_mb, env, timeout)


def _child(pkg: str, text: str, cap_mb: int, env: dict, timeout: float) -> dict:
    try:
        out = subprocess.run(
            [sys.executable, "-c", CHILD, pkg, str(cap_mb * 2**20)],
            input=text,
            capture_output=True,
            text=True,
            timeout=timeout,
            env=env,
        )
    except subprocess.TimeoutExpired:
        return {"error": f"over {timeout:.0f} s"}
    lines = out.stdout.strip().splitlines()
    if not lines:
        return {"error": f"exit {out.returncode}: {(out.stderr.strip().splitlines() or ['?'])[-1][:80]}"}
    return json.loads(lines[-1])


def fmt(r: dict) -> str:
    if "error" in r:
        return f"{r['error']} ({r.get('seconds', float('nan')):.1f} s, {r.get('rss_mb', float('nan')):.0f} MB)"
    if "refused" in r:
        return f"refused in {r['seconds']:.2f} s, {r['rss_mb']:.0f} MB"
    kernel = f" [{r['kernel']}]" if "kernel" in r else ""
    return f"{r['seconds']:.2f} s ({r['emit_s']:.2f} s without the report), {r['rss_mb']:.0f} MB{kernel}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default=BASE_COMMIT, help="the previous generator's commit")
    ap.add_argument("--cap-mb", type=int, default=1500, help="address-space cap of the previous generator's child")
    ap.add_argument("--form", default="covariance", choices=("covariance", "gain_schedule"))
    ap.add_argument("--no-cc", action="store_true", help="no C compiler reachable (CC=false, empty caches)")
    ap.add_argument("--case", action="append", default=[], help="only the models whose name contains this")
    args = ap.parse_args(argv)
    from accelnav.codegen.ranges import MAX_RUN_SAMPLES

    f = args.form
    cases = [
        ("100 Hz, 2 axes, 1 h", model_text(100.0, 3600.0, form=f)),
        ("1 kHz, 2 axes, 1 h", model_text(1000.0, 3600.0, form=f)),
        ("1 kHz, 3 axes, 1 h", model_text(1000.0, 3600.0, True, form=f)),
        (
            f"10 kHz, 2 axes, {MAX_RUN_SAMPLES / 1e4:.0f} s (longest accepted)",
            model_text(10000.0, MAX_RUN_SAMPLES / 1e4, form=f),
        ),
        ("100 kHz, 2 axes, 1800 s", model_text(100000.0, 1800.0, form=f)),
    ]
    cases = [c for c in cases if not args.case or any(t in c[0] for t in args.case)]
    with tempfile.TemporaryDirectory(prefix="acn_base_") as tmp:
        base_pkg = extract_base(args.base, Path(tmp))
        print(f"codegen + --report (fixed point, {args.form} form), child process; previous generator")
        print(f"= {args.base} capped at {args.cap_mb} MB of address space; peak RSS of the child")
        if args.no_cc:
            print("No C compiler reachable (CC=false, empty cache folders): [C] the kernel compiled into the package")
        print()
        print(f"| model | previous ({args.base}) | now | limit |")
        print("|---|---|---|---|")
        for name, text in cases:
            now = run_child("accelnav.codegen", text, 0, None, no_cc=args.no_cc)
            before = run_child(base_pkg, text, args.cap_mb, Path(tmp), no_cc=args.no_cc)
            print(f"| {name} | {fmt(before)} | {fmt(now)} | <= 5 s, <= 300 MB |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
