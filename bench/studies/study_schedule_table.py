"""How many pieces the gain schedule's table needs, by the kind of piece: the evidence behind issue #12's
2 KB target.

For one axis of a model at a rate: the float64 Kalman gains of the uninterrupted declared run (C
coordinates, in LSB of the generator's own gain formats) and the generator's own tolerance per gain and
sample (codegen.emit_c SCHEDULE_REL_TOL, SCHEDULE_FLOOR_LSB and the ramp of codegen.gains.schedule, plus
half an LSB). The run is then covered greedily by pieces on knots the four gains share: from each knot
the longest piece on which every gain's least-squares polynomial of its degree stays within MARGIN x its
tolerance (checked on every sample of a piece up to 4096 samples, on 4096 evenly spaced ones beyond).
Degree 0 is a held value (K_a today), 1 a straight line (K_r, K_v, K_e today).

What the counts are: the pieces may jump at the knots and their coefficients are real numbers, so a
table of integers that the C can walk needs at least about as many; the family "today" is checked against
the generator's own table, measured in the same run (its first line). Table bytes assume the cheapest
row of each family: an end word, one 4-byte number per coefficient (8 for K_e, whose slopes span 2^-32
to 2^28 LSB per sample), a straight or curved gain carrying its value from the previous piece (degree d:
d numbers), a held one its value.

    .venv/bin/python bench/studies/study_schedule_table.py [MODEL.toml] [--rate HZ] [--axis N] [--margin 1.0]
        [--family today quad_re quad cubic] [--per-gain]

Figures (2026-11-23, axis x, margin 1.0; pieces and table bytes; in brackets the pieces that fall in the
first 2000 samples):

    model, rate          the generator      today 1 1 0 1     quad_re 2 1 0 2   quad 2 2 1 2      cubic 3 3 1 3
    adxl250, 100 Hz      177, 4272 B        192 (79), 4632    52 (25), 1908     41 (16), 1680     23 (12), 1344
    adxl202 duty, 100 Hz 212, 5112 B        204 (108), 4920   40 (15), 1476     35 (13), 1440     17 (6), 1008
    adxl250, 1 kHz       412, 9912 B        254 (97), 6120    87 (59), 3168     58 (32), 2360     39 (28), 2240
    adxl250, 10 kHz      3667, 88032 B      331 (175), 7968   185 (164), 6696   94 (75), 3800     77 (70), 4368

"today" lands within 8 % of the generator's own count at 100 Hz; at 1 kHz and 10 kHz the generator needs
more (K_r's slope is a whole number of LSB per sample there). Higher-degree pieces fit 2 KB at 100 Hz, and
no family does at 1 kHz or 10 kHz: there the pieces crowd into the first 0.1-0.2 s, where K_a (held to
2e-7 of itself, about 5 % of K_e: the a / eps split) and K_e settle. Loosening K_a there to a fraction of
|K_e| was tried: at 5 % every state of the 100 Hz lockstep runs left the float64 filter by 2-4e-3 sigma
(from 2e-5 to 9e-4), so that tolerance is not slack.
"""

from __future__ import annotations

import argparse
import re
import sys
import time

import numpy as np

from accelnav.codegen.emit_c import SCHEDULE_FLOOR_LSB, SCHEDULE_REL_TOL, _schedule_for
from accelnav.codegen.gains import riccati
from accelnav.codegen.ranges import RangeError, plan_axis
from accelnav.model.load import ModelError, load_model, loads_model
from accelnav.resources import models_dir

TABLE_LIMIT = 2048
ROW_BYTES_TODAY = 24
COEF_BYTES = (4, 4, 4, 8)  # K_r, K_v, K_a, K_e
FAMILIES = {  # polynomial degree per gain (r, v, a, e)
    "today": (1, 1, 0, 1),
    "quad_re": (2, 1, 0, 2),
    "quad": (2, 2, 1, 2),
    "cubic": (3, 3, 1, 3),
}
CHECK = 4096  # samples checked per piece (all of a shorter one)


def model_at(path: str, rate: float | None):
    """The model with the gain-schedule form, at ``rate`` (its declared run cut to the longest accepted)."""
    m = load_model(path)
    text = re.sub(r'^form = "\w+"', 'form = "gain_schedule"', m.text, flags=re.M)
    if rate is not None and rate != m.rate_hz:
        text = re.sub(r"^rate_hz = .*$", f"rate_hz = {rate!r}", text, flags=re.M)
        if rate * m.ranges.max_run_s > 2**23:
            text = re.sub(r"^max_run_s = .*$", f"max_run_s = {2**23 // int(rate)}.0", text, flags=re.M)
    return loads_model(text, source=f"{path}@{rate or m.rate_hz:g}Hz")


def gains_and_tolerance(p) -> tuple[np.ndarray, np.ndarray]:
    """(n, 4) float64 gains in LSB of their formats, and the generator's tolerance per sample, in LSB."""
    n = p.n_run
    lsb = np.array([p.vars["K" + g].fmt.lsb for g in "rvae"])
    K = np.asarray(riccati(p.design, n, keep=n).K) * np.array([1.0, p.design.Ts, 1.0, 1.0]) / lsb
    rel = np.broadcast_to(np.asarray(SCHEDULE_REL_TOL, dtype=float), (n, 4)).copy()
    ramp = int(10 * p.model.rate_hz)  # as codegen.emit_c._schedule_for: K_r, K_v 20x tighter at first
    rel[:, :2] *= np.clip((np.arange(n) + 1.0) / ramp, 0.05, 1.0)[:, None]
    tol = np.maximum(rel * np.abs(K), np.asarray(SCHEDULE_FLOOR_LSB)) + 0.5
    return K, tol


def cover(K: np.ndarray, tol: np.ndarray, degrees, margin: float) -> list[int]:
    """Greedy piece lengths covering the run: longest feasible piece from each knot (doubling, then
    bisection; feasibility is close to monotone in the length, and the greedy is then optimal)."""
    n = len(K)
    gains = [g for g in range(4) if degrees[g] is not None]

    def fits(a: int, b: int) -> bool:
        idx = np.arange(a, b) if b - a <= CHECK else np.unique(np.linspace(a, b - 1, CHECK).astype(np.int64))
        t = (idx - a) / max(1, b - a)
        for g in gains:
            d = degrees[g]
            if len(idx) <= d + 1:
                continue
            V = np.vander(t, d + 1)
            c, *_ = np.linalg.lstsq(V, K[idx, g], rcond=None)
            if np.any(np.abs(V @ c - K[idx, g]) > margin * tol[idx, g]):
                return False
        return True

    out, a = [], 0
    while a < n:
        L = 1
        while a + 2 * L <= n and fits(a, a + 2 * L):
            L *= 2
        lo, hi = L, min(2 * L, n - a)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (mid, hi) if fits(a, a + mid) else (lo, mid)
        step = hi if fits(a, a + hi) else lo
        out.append(step)
        a += step
    return out


def row_bytes(degrees) -> int:
    """The cheapest row of a family: the end word and its coefficients (see the module docstring)."""
    return 4 + sum(cb * max(1, d) for d, cb in zip(degrees, COEF_BYTES, strict=True))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=str(models_dir() / "adxl250_default.toml"))
    ap.add_argument("--rate", type=float, default=None, help="sample rate, Hz (default: the model's)")
    ap.add_argument("--axis", type=int, default=0)
    ap.add_argument("--margin", type=float, default=1.0, help="fraction of the tolerance a fit may use")
    ap.add_argument("--per-gain", action="store_true", help="also each gain alone: which one sets the count")
    ap.add_argument("--family", nargs="+", default=list(FAMILIES), choices=list(FAMILIES))
    a = ap.parse_args(argv)
    try:
        model = model_at(a.model, a.rate)
        p = plan_axis(model, a.axis, "gain_schedule")
    except (OSError, ModelError, RangeError, ValueError) as e:
        print(f"study_schedule_table: {e}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    sched = _schedule_for(p)
    base = (sched.n_segments + 1) * ROW_BYTES_TODAY
    print(f"{model.source}, axis {model.axes[a.axis].name}: {p.n_run} samples, margin {a.margin}")
    print(f"the generator's table: {sched.n_segments} segments, {base} B ({time.perf_counter() - t0:.1f} s)")
    K, tol = gains_and_tolerance(p)
    print(f"{'family':8s} {'degrees r v a e':15s} {'pieces':>6s} {'first 2000':>10s} {'row B':>6s} {'table B':>8s}")
    for name in a.family:
        deg = FAMILIES[name]
        t0 = time.perf_counter()
        lengths = cover(K, tol, deg, a.margin)
        first = int(np.searchsorted(np.cumsum(lengths), 2000, side="right")) + 1
        rb = row_bytes(deg)
        nb = (len(lengths) + 1) * rb
        verdict = "fits 2 KB" if nb <= TABLE_LIMIT else "over 2 KB"
        print(
            f"{name:8s} {' '.join(map(str, deg)):15s} {len(lengths):6d} {min(first, len(lengths)):10d} {rb:6d} "
            f"{nb:8d}  {verdict} ({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
        if a.per_gain:
            alone = []
            for g in range(4):
                one = [None] * 4
                one[g] = deg[g]
                lg = cover(K, tol, one, a.margin)
                alone.append(f"{'rvae'[g]} {len(lg)} ({int(np.searchsorted(np.cumsum(lg), 2000, side='right')) + 1})")
            print(f"{'':8s} each gain alone, pieces (in the first 2000 samples): {', '.join(alone)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
