"""Benchmark (issue 24): the general smoother kernel alone, ns per sample per axis, this build beside a baseline.

The general path (fixes, rests) as `smooth --zupt auto` drives it: half the samples in rests (a
zero-velocity update each), a position fix every 1e4 samples, one sample in 37 invalid. Times, best of
--repeat, with buffers reused (no page faults): acn_general (filter, store, smoother, whole run), the
bounded path's acn_chunkg_fwd and acn_chunkg_bwd over one chunk, and the three kernels `smooth` runs on an
aided axis (its lean store): acn_chunkg_fwd_lean (no filter states wanted), acn_chunkg_cov (the covariances
made again) and acn_chunkg_bwd_lean; and acn_chunkg_fwd_lean once more into a fresh store, as the bounded run
writes it (chunked.fresh_array: the pages are faulted in and zeroed as the rows are written, in the thread's
system time). Times are the calling thread's CPU seconds (time.thread_time: on a
machine shared with other work, wall time counts theirs, and a process's CPU time counts idle BLAS threads). The
baseline runs this very script with its own python (default /work/main/.venv) in a subprocess, the builds
alternating over --rounds (the other first each round), the best of all kept.
Usage: python bench/run_all.py speed --only bench_general_kernel, or from bench/speed:
  python bench_general_kernel.py [--n 1e6] [--baseline /work/main] [--repeat 3] [--rounds 3]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from baselines import builds as baseline_builds  # bench/common, on the path bench/run_all.py sets


def measure(n: int, repeat: int) -> dict[str, float]:
    from accelnav.estimate import chunked, fastsmooth
    from accelnav.estimate.fastsmooth import Extras
    from accelnav.estimate.kf import position_fix, zero_velocity
    from accelnav.model.design import axis_design
    from accelnav.model.load import load_model

    d = axis_design(load_model(None), 0)
    rng = np.random.default_rng(1)
    z = rng.normal(0.0, 0.05, n)
    valid = np.ones(n, dtype=bool)
    valid[::37] = False
    k = np.arange(n)
    rest = k[(k // 500) % 2 == 0]
    aids = [zero_velocity(int(i), 1e-3) for i in rest] + [position_fix(i, 0.0, 1.0) for i in range(100, n, 10_000)]
    ex = Extras.of(aids)
    names = ("acn_general", "acn_chunkg_fwd", "acn_chunkg_bwd", "acn_chunkg_fwd_lean", "acn_chunkg_cov")
    fresh_row = "acn_chunkg_fwd_lean, fresh store"
    best = dict.fromkeys((*names, "acn_chunkg_bwd_lean", fresh_row), np.inf)
    out = fastsmooth.smooth_general(d, z, valid=valid, extras=ex)
    mod = fastsmooth._lib()
    ffi, lib = mod.ffi, mod.lib

    def p(a, t="double *"):
        return ffi.cast(t, ffi.from_buffer(a))

    ax = fastsmooth._axis_struct(ffi, d)
    # the covariance outputs (NULL: not written), which a baseline built before them does not take
    fwd_cov = (ffi.NULL,) * (len(ffi.typeof(lib.acn_chunkg_fwd).args) - 16)
    bwd_cov = (ffi.NULL,) * (len(ffi.typeof(lib.acn_chunkg_bwd).args) - 8)
    lean_nis = (ffi.NULL,) * (len(ffi.typeof(lib.acn_chunkg_fwd_lean).args) - 16)  # the aids' y, S: not wanted
    store, xa, sa = np.empty((n, 14)), np.empty((n, 4)), np.empty((n, 4))
    lean, pst = np.empty((n, 4)), np.empty((n, 10))
    gates, applied = np.zeros(len(ex)), np.zeros(len(ex), dtype=np.uint8)
    ek = ffi.from_buffer("long[]", ex.k)
    for _ in range(repeat):
        t = time.thread_time()
        fastsmooth.smooth_general(d, z, valid=valid, extras=ex, out=out)
        best["acn_general"] = min(best["acn_general"], time.thread_time() - t)
        carry_f = np.concatenate([np.asarray(d.x0, dtype=float), fastsmooth.pack(np.asarray(d.P0, dtype=float))])
        carry_b = np.zeros(14)
        t0 = time.thread_time()
        lib.acn_chunkg_fwd(
            ax, n, 1, p(z), p(valid.view(np.uint8), "unsigned char *"), len(ex), ek, p(ex.h), p(ex.z), p(ex.R),
            p(gates), p(applied, "unsigned char *"), p(carry_f), p(store), p(xa), p(sa), *fwd_cov,
        )  # fmt: skip
        t1 = time.thread_time()
        if lib.acn_chunkg_bwd(ax, 0, n, 1, p(store), p(carry_b), p(xa), p(sa), *bwd_cov) != 0:
            raise SystemExit("acn_chunkg_bwd refused the run")
        t2 = time.thread_time()
        best["acn_chunkg_fwd"] = min(best["acn_chunkg_fwd"], t1 - t0)
        best["acn_chunkg_bwd"] = min(best["acn_chunkg_bwd"], t2 - t1)
        carry_f = np.concatenate([np.asarray(d.x0, dtype=float), fastsmooth.pack(np.asarray(d.P0, dtype=float))])
        p0 = carry_f[4:].copy()
        t0 = time.thread_time()
        lib.acn_chunkg_fwd_lean(
            ax, n, 1, p(z), p(valid.view(np.uint8), "unsigned char *"), len(ex), ek, p(ex.h), p(ex.z), p(ex.R),
            p(gates), p(applied, "unsigned char *"), p(carry_f), p(lean), ffi.NULL, ffi.NULL, *lean_nis,
        )  # fmt: skip
        t1 = time.thread_time()
        lib.acn_chunkg_cov(
            ax, n, 1, p(valid.view(np.uint8), "unsigned char *"), len(ex), ek, p(ex.h), p(ex.R),
            p(applied, "unsigned char *"), p(p0), p(pst),
        )  # fmt: skip
        t2 = time.thread_time()
        if lib.acn_chunkg_bwd_lean(ax, 0, n, 1, p(lean), p(pst), p(np.zeros(14)), p(xa), p(sa)) != 0:
            raise SystemExit("acn_chunkg_bwd_lean refused the run")
        t3 = time.thread_time()
        for key, v in zip(names[3:] + ("acn_chunkg_bwd_lean",), (t1 - t0, t2 - t1, t3 - t2), strict=True):
            best[key] = min(best[key], v)
        fresh = chunked.fresh_array((n, 4))
        carry_f = np.concatenate([np.asarray(d.x0, dtype=float), fastsmooth.pack(np.asarray(d.P0, dtype=float))])
        t0 = time.thread_time()
        lib.acn_chunkg_fwd_lean(
            ax, n, 1, p(z), p(valid.view(np.uint8), "unsigned char *"), len(ex), ek, p(ex.h), p(ex.z), p(ex.R),
            p(gates), p(applied, "unsigned char *"), p(carry_f), p(fresh), ffi.NULL, ffi.NULL, *lean_nis,
        )  # fmt: skip
        best[fresh_row] = min(best[fresh_row], time.thread_time() - t0)
        np.testing.assert_array_equal(fresh, lean)  # the same rows as into the store in use
        del fresh
    return {key: v * 1e9 / n for key, v in best.items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=float, default=1e6)
    ap.add_argument("--baseline", type=Path, default=Path("/work/main"), help="checkout with its own .venv")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=3, help="runs of each build, alternating")
    ap.add_argument("--inner", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    n = int(args.n)
    if args.inner:
        print(json.dumps(measure(n, args.repeat)))
        return 0
    builds = baseline_builds(args.baseline)
    res: dict[str, dict[str, float]] = {}
    failed: set[str] = set()
    for r in range(args.rounds):
        for build, py in list(builds.items())[:: 1 if r % 2 == 0 else -1]:
            if build in failed:
                continue
            cmd = [py, __file__, "--inner", "--n", str(n), "--repeat", str(args.repeat)]
            got = subprocess.run(cmd, capture_output=True, text=True, check=False)
            if got.returncode:
                print(f"{build} failed: {got.stderr.strip().splitlines()[-1:]}")
                failed.add(build)
                res.pop(build, None)
                continue
            new = json.loads(got.stdout.strip().splitlines()[-1])
            res[build] = {k: min(v, res.get(build, new)[k]) for k, v in new.items()}
    res = {b: res[b] for b in builds if b in res}  # this, then the baseline
    print(f"General smoother kernel, N = {n:.0e}, ns per sample per axis (best of {args.repeat} x {args.rounds}):\n")
    print("| kernel | " + " | ".join(res) + (" | baseline / this |" if len(res) == 2 else " |"))
    print("|---|" + "---|" * (len(res) + (len(res) == 2)))
    for key in next(iter(res.values()), {}):
        row = " | ".join(f"{res[b][key]:.0f}" for b in res)
        ratio = f" | {res['baseline'][key] / res['this'][key]:.2f}" if len(res) == 2 else ""
        print(f"| {key} | {row}{ratio} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
