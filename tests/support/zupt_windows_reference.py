"""The rest detector's candidates as main computed them before issue 32 moved two of its passes to C: ``_prepared``
(now acn_rest_prepare), ``_moving`` and ``_detect`` (its window pass, now acn_rest_windows) copied from main's
accelnav.estimate.zupt, the window pass at the head of ``_detect`` lifted verbatim into :func:`windows`. The
oracle the compiled passes must agree with, double for double. Test support only; do not "fix" it. The steps
after the window pass (the split into pieces, the widening, the joins) are the package's own: this module holds
only what changed.
"""

from __future__ import annotations

import numpy as np

from accelnav.estimate.kf import bias_model
from accelnav.estimate.zupt import ZuptParams, _level_steps, _steady_pieces, intervals, resolved, window_samples
from accelnav.model.design import axis_design
from accelnav.model.load import Model


def _prepared(accel, clipped, model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, ok, R): acceleration minus the bias mean (0 where unusable), the usable mask, R per axis."""
    accel = np.asarray(accel, dtype=np.float64)
    clipped = np.asarray(clipped, dtype=bool)
    n, n_axes = accel.shape
    x = np.empty((n, n_axes))
    ok = ~clipped & np.isfinite(accel)
    R = np.empty(n_axes)
    powers: dict[float, np.ndarray] = {}  # phi^k per bias time constant: the axes of a model mostly share one
    for j in range(n_axes):
        d = axis_design(model, j)
        if d.phi not in powers:
            powers[d.phi] = d.phi ** np.arange(n)
        x[:, j] = np.where(ok[:, j], accel[:, j] - bias_model(d, n, powers[d.phi]), 0.0)
        R[j] = d.R
    return x, ok, R


def candidates(accel: np.ndarray, clipped: np.ndarray, model: Model, params: ZuptParams) -> np.ndarray:
    p = resolved(model, params)
    return _detect(*_prepared(accel, clipped, model), model, p)


def windows(x: np.ndarray, ok: np.ndarray, R: np.ndarray, w: int, tremor: float, var_k: float):
    """(means, wvar, centre, quiet) as :func:`_detect`'s opening lines computed them (accelnav.estimate.zupt._windows;
    quiet returned besides, for a test that puts a window on the bound)."""
    n, n_axes = x.shape
    bad = _moving((~ok.all(axis=1)).astype(np.float64), w)
    quiet = np.zeros(n)
    wvar = np.zeros(n)
    means = np.empty((n, n_axes))
    for j in range(n_axes):
        s1 = _moving(x[:, j], w)
        s2 = _moving(x[:, j] * x[:, j], w)
        with np.errstate(invalid="ignore", over="ignore"):
            means[:, j] = s1 / w
            v = (s2 - w * means[:, j] ** 2) / (w - 1)
            quiet += v / (R[j] + tremor**2)
            wvar += v
    with np.errstate(invalid="ignore"):
        centre = (bad == 0) & (quiet / n_axes <= var_k)
    return means, wvar, centre, quiet


def _moving(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving sum over w (odd) samples; NaN where the window leaves the run."""
    n = len(x)
    out = np.full(n, np.nan)
    if n < w:
        return out
    c = np.concatenate(([0.0], np.cumsum(x)))
    h = w // 2
    out[h : n - h] = c[w:] - c[: n - w + 1]
    return out


def _detect(x: np.ndarray, ok: np.ndarray, R: np.ndarray, model: Model, p: ZuptParams) -> np.ndarray:
    """:func:`candidates` on the prepared record (:func:`_prepared`), which the decision reads too."""
    n, n_axes = x.shape
    w = window_samples(model, p)
    means, wvar, centre, _ = windows(x, ok, R, w, p.tremor, p.var_k)
    # split each run into pieces of steady level: a move that starts gently is quiet, but its mean walks away
    total = float(np.sum(R + p.tremor**2))
    bound2 = p.trim_k**2 * total / w
    runs = intervals(centre)
    # a body swaying more than the tremor allowance (a real stance) has a level that wanders as much: the bound
    # grows with the run's own typical window variance (not with a ramp, whose windows stay quiet)
    pieces = [
        (*q, k)
        for k, (a, b) in enumerate(runs)
        for q in _steady_pieces(
            means,
            a,
            b,
            bound2 * max(1.0, float(np.median(wvar[a:b])) / total),
            x,
            total,
            w,
            p.level_rate * model.Ts,
            int(round(model.rate_hz)),  # a lean is told from a ramp over more than a second
            p.leak_rate * model.Ts,
        )
    ]  # in sample order: runs are, and so are the pieces of each
    # widen each piece towards its windows' extent (every sample of a passing window was quiet), sample by
    # sample while a sample stays within trim_k sd of the piece's level: a heel strike or the start of a ramp
    # ends it. Join pieces at one level across short breaks (a knock fails every window that holds it);
    # pieces at two levels stay apart by a sample at least, so each is judged on its own
    h = int(round(p.widen * (w // 2)))
    bridge = int(round(p.bridge_s * model.rate_hz))
    usable = ok.all(axis=1)
    starts = np.array([q[0] for q in pieces], dtype=np.int64)
    stops = np.array([q[1] for q in pieces], dtype=np.int64)
    refs = np.array([q[2] for q in pieces]).reshape(len(pieces), n_axes)
    lim2 = p.trim_k**2 * np.array([q[3] for q in pieces])
    starts = starts - _level_steps(x, usable, refs, lim2, starts, -1, h)
    stops = stops + _level_steps(x, usable, refs, lim2, stops - 1, 1, h)
    merged: list[list] = []
    for (_, _, ref, _, run), a, b in zip(pieces, starts.tolist(), stops.tolist(), strict=True):
        if (
            merged
            and run != merged[-1][3]  # a break that failed the quiet test, not a change of level
            and a - merged[-1][1] <= bridge
            and np.sum((ref - merged[-1][2]) ** 2) <= bound2
            and usable[merged[-1][1] : a].all()  # a knock, not clipped or missing samples
        ):
            merged[-1][1] = b
            merged[-1][3] = run
        else:
            if merged:
                a = max(a, merged[-1][1] + 1)
            merged.append([a, b, ref, run])
    shortest = max(1, int(round(p.min_rest_s * model.rate_hz)))
    kept = np.array([(a, b) for a, b, _, _ in merged if b - a >= shortest], dtype=np.int64).reshape(-1, 2)
    edges = np.zeros(n + 1, dtype=np.int64)
    np.add.at(edges, kept[:, 0], 1)
    np.add.at(edges, kept[:, 1], -1)
    return np.cumsum(edges[:n]) > 0
