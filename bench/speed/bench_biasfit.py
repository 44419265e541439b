"""Bench: bias fit, whiteness tests and noise identification on 1e6 and 1e7 samples, each stage timed.

The fit runs beside scipy's plain ``curve_fit`` of the same three-parameter
model on the same data in the same run, from two starting points: curve_fit's
default (all ones) and an automatic guess (levels of the first and last
minute, T = a tenth of the record). Printed: seconds per stage, the speed
ratio, and whether each converged to the answer (within 1e-3 of our T
relative, or not at all).

The recording: 100 Hz, c1 = 0.08 m/s^2, c2 = 0.05 m/s^2, T = 300 s (the
default ADXL250 model), white noise of 0.126 m/s^2 rms; 1e6 samples is 2.8 h,
1e7 samples 28 h, so the warm-up fills 3 % and 0.3 % of the record.

    .venv/bin/python bench/speed/bench_biasfit.py [--sizes 1e6 1e7] [--no-curve-fit]
"""

from __future__ import annotations

import argparse
import platform
import time
import warnings

import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit

from accelnav.identify.biasfit import fit_bias
from accelnav.identify.noiseid import identify_noise
from accelnav.identify.whiteness import whiteness

RATE = 100.0
C1, C2, T_TRUE, SIGMA = 0.08, 0.05, 300.0, 0.126


class StageClock:
    """Stands in for a Progress: records when each stage of fit_bias finishes."""

    def __init__(self):
        self.t0 = time.perf_counter()
        self.marks: list[float] = []
        self.total = 0

    def update(self, done: int) -> None:
        self.marks.append(time.perf_counter())


def model(t, c1, c2, T):
    return c1 * (1.0 - np.exp(-t / T)) + c2


def run_curve_fit(t, y, p0, label: str, ours_T: float) -> dict:
    t0 = time.perf_counter()
    status = "converged"
    popt = None
    nfev = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OptimizeWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            popt, _, info, mesg, ier = curve_fit(model, t, y, p0=p0, full_output=True)
            nfev = info.get("nfev")
            if ier not in (1, 2, 3, 4):
                status = f"failed (ier {ier}: {mesg.strip()[:60]})"
        except RuntimeError as exc:
            status = f"failed ({str(exc).strip()[:70]})"
    dt = time.perf_counter() - t0
    if popt is not None and status == "converged":
        if not (np.all(np.isfinite(popt)) and abs(popt[2] / ours_T - 1) < 1e-3):
            status = f"converged elsewhere (T = {popt[2]:.4g} s, c1 = {popt[0]:.4g})"
    return {"label": label, "seconds": dt, "status": status, "popt": popt, "nfev": nfev}


def bench(n: int, seed: int, do_curve_fit: bool) -> None:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    y = model(t, C1, C2, T_TRUE) + SIGMA * rng.standard_normal(n)
    print(f"\n== n = {n:.0e} samples ({n / RATE / 3600:.3g} h at {RATE:g} Hz)")

    clock = StageClock()
    start = time.perf_counter()
    f = fit_bias(t, y, progress=clock)
    fit_s = time.perf_counter() - start
    stages = np.diff([start, *clock.marks])
    names = ("profile sums (one pass)", "grid + Brent on log T", "exact pass, Jacobian, polish", "intervals, verdict")
    for name, s in zip(names, stages, strict=True):
        print(f"   fit: {name:<32} {s:8.3f} s")
    print(f"   fit: {'total':<32} {fit_s:8.3f} s   ({n / fit_s:,.0f} samples/s)")
    print(
        f"        c1 = {f.c1:.5f} [{f.ci95[0][0]:.5f}, {f.ci95[0][1]:.5f}]  c2 = {f.c2:.5f} "
        f"[{f.ci95[1][0]:.5f}, {f.ci95[1][1]:.5f}]  T = {f.T:.2f} [{f.ci95[2][0]:.2f}, {f.ci95[2][1]:.2f}] s"
        f"  ({f.verdict.split(':')[0]})"
    )

    start = time.perf_counter()
    w = whiteness(f.residuals)
    white_s = time.perf_counter() - start
    print(
        f"   whiteness (Ljung-Box, ACF band, periodogram) {white_s:8.3f} s   " + "; ".join(t.verdict for t in w.tests)
    )

    start = time.perf_counter()
    nz = identify_noise(f.residuals, RATE)
    noise_s = time.perf_counter() - start
    print(
        f"   noise id (Allan {len(nz.curve.tau)} taus + terms)    {noise_s:8.3f} s   N = {nz.terms.N:.5g} "
        f"(truth {SIGMA / np.sqrt(RATE):.5g}), K {'<=' if nz.terms.K_is_bound else '='} {nz.terms.K:.3g}"
    )
    print(f"   all three stages                      {fit_s + white_s + noise_s:8.3f} s")

    if not do_curve_fit:
        return
    first = y[: int(60 * RATE)].mean()
    last = y[-int(60 * RATE) :].mean()
    starts = [(None, "curve_fit, default p0 = (1, 1, 1)"), ((last - first, first, t[-1] / 10), "curve_fit, guessed p0")]
    for p0, label in starts:
        r = run_curve_fit(t, y, p0, label, f.T)
        extra = f", {r['nfev']} evaluations" if r["nfev"] is not None else ""
        print(f"   {label:<38} {r['seconds']:8.3f} s   {r['seconds'] / fit_s:6.1f}x our fit; {r['status']}{extra}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e6, 1e7])
    ap.add_argument("--no-curve-fit", action="store_true")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    print(
        f"bench_biasfit on {platform.machine()}, numpy {np.__version__}, python {platform.python_version()}; "
        "times are wall-clock seconds after a warm-up"
    )
    # warm up both methods (imports, first-call set-up) so that the timed runs compare the algorithms
    tw = np.arange(20_000) / RATE
    yw = model(tw, C1, C2, 40.0) + SIGMA * np.random.default_rng(0).standard_normal(len(tw))
    fit_bias(tw, yw)
    whiteness(yw)
    identify_noise(yw, RATE)
    run_curve_fit(tw, yw, (0.1, 0.0, 20.0), "warm-up", 40.0)
    for n in args.sizes:
        bench(int(n), args.seed, not args.no_curve_fit)


if __name__ == "__main__":
    main()
