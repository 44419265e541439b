"""Study (issue 32): does the general (aided) path's covariance reach a bitwise fixed point between aids?

The plain path skips its covariance work at a fixed point (its steady rows): there the (a, eps) block, the only
one the acceleration sees, repeats its bits from one sample to the next. The proposal for the aided path was the
same: where the prior covariance a step starts from has the bits of the previous step's, the step's gain, posterior
and smoother gain are the same doubles, so reuse them. This study measures, before anyone builds it, how often that
holds. It runs the general path's own kernels (acn_chunkg_fwd, acn_chunkg_bwd) on the default model's axes and
counts, sample by sample:

* the filter's posterior covariance (all 10 packed entries; what the gain, the covariance made again and the
  smoother gain depend on) with the same bits as the previous sample's, and only as the one two samples back
  (a 2-cycle in the last ulp);
* the same for its (a, eps) block alone and for the smoothed covariance;
* P_rr (position variance) at the start and end of the longest stretch without an aid.

Scenarios: the e2e bench's aids (a fix per axis every 60 s, sd 5 m; a rest of 1 s every 30 s), a rest at every
sample (a stationary recording under ``--zupt auto``), and no aid at all (the plain path's case). The (a, eps)
block is the control that the count finds a fixed point where there is one: it settles under rests at every
sample, and without aids after a few 1e5 samples (the plain path's transient). Every sample's acceleration is
valid: a gap only moves the covariance further from any fixed point.
Usage: python bench/run_all.py bench/studies/study_general_fixed_point.py [--n 1e6]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def _runs(lib, ffi, ax, d, n: int, ex) -> tuple[np.ndarray, np.ndarray]:
    """(filter posterior covariances, smoothed covariances), packed, n x 10 each."""
    from accelnav.estimate import fastsmooth

    def p(a, t="double *"):
        return fastsmooth._ptr(ffi, a, t)

    ne = len(ex)
    ek = ex.k if ne else np.zeros(1, dtype=np.int64)
    eh, ez, eR = (ex.h, ex.z, ex.R) if ne else (np.zeros(4),) * 3
    gates, applied = np.zeros(max(ne, 1)), np.zeros(max(ne, 1), dtype=np.uint8)
    carry = np.concatenate([np.asarray(d.x0, dtype=float), fastsmooth.pack(np.asarray(d.P0, dtype=float))])
    store, xa, sa, ps = np.empty((n, 14)), np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 10))
    z = np.zeros(n)
    lib.acn_chunkg_fwd(ax, n, 1, p(z), ffi.NULL, ne, ffi.from_buffer("long[]", ek), p(eh), p(ez), p(eR), p(gates),
                       p(applied, "unsigned char *"), p(carry), p(store), p(xa), p(sa), ffi.NULL, ffi.NULL)  # fmt: skip
    if lib.acn_chunkg_bwd(ax, 0, n, 1, p(store), p(np.zeros(14)), p(xa), p(sa), p(ps)) != 0:
        raise SystemExit("acn_chunkg_bwd refused the run")
    return store[:, 4:].copy(), ps


def _repeats(P: np.ndarray, cols) -> tuple[float, float]:
    """(fraction of samples whose columns repeat the previous sample's bits, fraction repeating only 2 back)."""
    b = np.ascontiguousarray(P[:, cols]).view(np.uint64)
    one = np.r_[False, np.all(b[1:] == b[:-1], axis=1)]
    two = np.r_[False, False, np.all(b[2:] == b[:-2], axis=1)]
    return float(one.mean()), float((two & ~one).mean())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=float, default=1e6, help="samples per scenario")
    args = ap.parse_args()
    from accelnav.estimate import fastsmooth
    from accelnav.estimate.fastsmooth import Extras
    from accelnav.estimate.kf import position_fix, zero_velocity
    from accelnav.model.design import axis_design
    from accelnav.model.load import load_model

    model = load_model(None)
    n, rate = int(args.n), model.rate_hz
    k = np.arange(n)
    every_60 = [position_fix(int(round(t * rate)), 0.0, 5.0) for t in np.arange(1.0, n / rate, 60.0)]
    rest_1_in_30 = [zero_velocity(int(i)) for i in k[(k >= 5 * rate) & ((k - 5 * rate) % (30 * rate) <= rate)]]
    scenarios = {
        "e2e bench: fix every 60 s, rest 1 s every 30 s": every_60 + rest_1_in_30,
        "rest at every sample (stationary, --zupt auto)": [zero_velocity(int(i)) for i in k],
        "no aid (the plain path's case: control)": [],
    }
    mod = fastsmooth._lib()
    ae = [7, 8, 9]  # packed AA, AE, EE
    print(f"General path, default model, N = {n:.0e} a scenario, every acceleration valid.\n")
    print("Fraction of samples whose covariance has the previous sample's bits (2-cycle: only those of two back).\n")
    print("| scenario | axis | filter P | 2-cycle | filter (a, eps) | 2-cycle | smoothed P | 2-cycle | P_rr |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, aids in scenarios.items():
        ex = Extras.of(aids) if aids else Extras.of([])
        aided = np.zeros(n, dtype=bool)
        aided[ex.k] = True
        idx = np.r_[-1, np.flatnonzero(aided), n]
        g = int(np.argmax(np.diff(idx)))  # the longest stretch without an aid: samples idx[g]+1 .. idx[g+1]-1
        a, b = idx[g] + 1, idx[g + 1] - 1
        for j in range(len(model.axes)):
            d = axis_design(model, j)
            P, S = _runs(mod.lib, mod.ffi, fastsmooth._axis_struct(mod.ffi, d), d, n, ex)
            cells = [*_repeats(P, range(10)), *_repeats(P, ae), *_repeats(S, range(10))]
            grew = f"{P[a, 0]:.3g} to {P[b, 0]:.3g} over {b - a} samples" if b > a else "(no stretch)"
            print(f"| {name} | {j} | " + " | ".join(f"{c:.4f}" for c in cells) + f" | {grew} |")
    print(
        "\nP_rr: the position variance at the start and the end of the longest stretch without an aid. Position is "
        "not observed through the acceleration, so P_rr grows at every step between fixes (rests hold the "
        "velocity, not the position): the packed covariance, its gain and the smoother gain never repeat, and "
        "the reuse has nothing to reuse."
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
