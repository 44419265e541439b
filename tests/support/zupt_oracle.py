"""The rest detector's candidates as they were before issue 24 made them array code (main at 03f236d,
accelnav.estimate.zupt): the oracle the new one must agree with, sample for sample. Test support only;
not part of the package. Copied verbatim (docstrings shortened); do not "fix" it. (Its chain of per-rest
gates is gone: issue 31 replaced the decision, tests/estimate/test_rest_decision.py tests the new one.)
Issue 31 changed the split into pieces twice, and both changes are made here too: a part with no window near
its median is halved instead of dropped, and a piece that is its whole run may drift at ``leak_rate``.
Issue 32 lifted the window pass out of :func:`candidates` into :func:`windows`, unchanged, to hold the C that
replaced it to the same doubles.
"""

from __future__ import annotations

import math

import numpy as np

from accelnav.estimate.kf import bias_model
from accelnav.estimate.zupt import ZuptParams, resolved, window_samples
from accelnav.model.design import axis_design
from accelnav.model.load import Model


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


def _prepared(accel, clipped, model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, ok, R): acceleration minus the bias mean (0 where unusable), the usable mask, R per axis."""
    accel = np.asarray(accel, dtype=np.float64)
    clipped = np.asarray(clipped, dtype=bool)
    n, n_axes = accel.shape
    x = np.empty((n, n_axes))
    ok = ~clipped & np.isfinite(accel)
    R = np.empty(n_axes)
    for j in range(n_axes):
        d = axis_design(model, j)
        x[:, j] = np.where(ok[:, j], accel[:, j] - bias_model(d, n), 0.0)
        R[j] = d.R
    return x, ok, R


def windows(x: np.ndarray, ok: np.ndarray, R: np.ndarray, w: int, tremor: float, var_k: float):
    """(means, wvar, centre, quiet): the window pass at the head of :func:`candidates`, lifted out unchanged (issue
    32 compiled it, acn_rest_centres and acn_rest_span; tests/estimate/test_zupt_windows.py holds the C to these
    doubles)."""
    n, n_axes = x.shape
    bad = _moving((~ok.all(axis=1)).astype(np.float64), w)
    quiet = np.zeros(n)
    wvar = np.zeros(n)  # window variance, summed over the axes
    means = np.empty((n, n_axes))
    for j in range(n_axes):
        s1 = _moving(x[:, j], w)
        s2 = _moving(x[:, j] * x[:, j], w)
        with np.errstate(invalid="ignore"):
            means[:, j] = s1 / w
            v = (s2 - w * means[:, j] ** 2) / (w - 1)
            quiet += v / (R[j] + tremor**2)
            wvar += v
    with np.errstate(invalid="ignore"):
        centre = (bad == 0) & (quiet / n_axes <= var_k)
    return means, wvar, centre, quiet


def candidates(accel: np.ndarray, clipped: np.ndarray, model: Model, params: ZuptParams) -> np.ndarray:
    """(N,) bool: samples the detector calls rest, before the per-rest decision (see the module docstring).

    ``accel``, ``clipped`` are (N, n_axes) as in a run file; columns are the model's axes in order.
    """
    p = resolved(model, params)
    x, ok, R = _prepared(accel, clipped, model)
    n, n_axes = x.shape
    w = window_samples(model, p)
    means, wvar, centre, _ = windows(x, ok, R, w, p.tremor, p.var_k)
    # split each run into pieces of steady level: a move that starts gently is quiet, but its mean walks away
    total = float(np.sum(R + p.tremor**2))
    bound2 = p.trim_k**2 * total / w
    runs = intervals(centre)
    # a body swaying more than the tremor allowance (a real stance) has a level that wanders as much: the bound
    # grows with the run's own typical window variance (not with a ramp, whose windows stay quiet)
    pieces = sorted(
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
    )
    # widen each piece towards its windows' extent (every sample of a passing window was quiet), sample by
    # sample while a sample stays within trim_k sd of the piece's level: a heel strike or the start of a ramp
    # ends it. Join pieces at one level across short breaks (a knock fails every window that holds it);
    # pieces at two levels stay apart by a sample at least, so each is judged on its own
    h = int(round(p.widen * (w // 2)))
    bridge = int(round(p.bridge_s * model.rate_hz))
    usable = ok.all(axis=1)
    merged: list[list] = []
    for a, b, ref, own, run in pieces:
        lim2 = p.trim_k**2 * own
        lo, hi = max(0, a - h), min(n, b + h)
        while a > lo and usable[a - 1] and np.sum((x[a - 1] - ref) ** 2) <= lim2:
            a -= 1
        while b < hi and usable[b] and np.sum((x[b] - ref) ** 2) <= lim2:
            b += 1
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
    rest = np.zeros(n, dtype=bool)
    shortest = max(1, int(round(p.min_rest_s * model.rate_hz)))
    for a, b, _, _ in merged:
        if b - a >= shortest:
            rest[a:b] = True
    return rest


def _steady_pieces(
    means: np.ndarray,
    a: int,
    b: int,
    bound2: float,
    x: np.ndarray,
    total: float,
    w: int,
    tilt_rate: float,
    lean: int,
    leak_rate: float,
) -> list[tuple[int, int, np.ndarray]]:
    """Split the run [a, b) of window centres into pieces whose window means stay within sqrt(bound2) of the
    piece's median: the longest such stretch about the run's median is kept, the parts either side are split
    again. The ends of a piece are trimmed again with the bound scaled to the piece's own variance (of ``x``,
    summed over axes, against ``total``, the sum of R + tremor^2) when that is smaller; a piece whose first
    and last thirds differ by more than trim_k sd of a window mean (from the piece's own variance) plus
    ``tilt_rate`` (m/s^2 per sample) times their distance beyond ``lean`` samples is a stretch of a ramp
    and dropped. What the trim cuts off a piece is split again; a piece from it is kept when it holds three
    windows at least and its level does not walk away from the piece it was cut from (see below).
    Returns (first, last + 1, median level, own variance) per piece."""
    out = []
    run = (a, b)
    todo: list[tuple[int, int, np.ndarray | None, int]] = [(a, b, None, 0)]
    while todo:
        a, b, parent, side = todo.pop()
        if b <= a:
            continue
        whole = (a, b) == run and parent is None
        ref = np.median(means[a:b], axis=0)
        near = np.sum((means[a:b] - ref) ** 2, axis=1) <= bound2
        runs = intervals(near)
        if not runs:
            if parent is None and b - a >= 2:  # issue 31: halved, each half split on its own
                h = a + (b - a) // 2
                todo += [(a, h, None, 0), (h, b, None, 0)]
            continue
        p, q = max(runs, key=lambda r: r[1] - r[0])
        todo += [(a, a + p, None, 0), (a + q, b, None, 0)]
        p, q = a + p, a + q
        # the ends, once more, against the piece's own noise (quieter than the tremor allows, on most rests)
        ref = np.median(means[p:q], axis=0)
        own = float(np.sum(x[p:q].var(axis=0)))
        own2 = min(bound2, bound2 * own / total)
        near = np.flatnonzero(np.sum((means[p:q] - ref) ** 2, axis=1) <= own2)
        if not len(near):
            continue
        # what the trim cuts off is split again: a standing whose level stepped (by 0.1 m/s^2 on a real
        # lower-back recording, no rotation on the gyroscope) keeps its second level as a piece of its own
        todo += [(p, p + int(near[0]), ref, -1), (p + int(near[-1]) + 1, q, ref, 1)]
        p, q = p + int(near[0]), p + int(near[-1]) + 1
        # the level still moving across the piece: part of a ramp, not a rest (trim_k sd of a window mean, from
        # the piece's own variance: a sway beyond the tremor allowance is noise here, not a ramp), unless it
        # moves no faster than a tilt may over more than ``lean`` samples (level_rate: a person standing leans
        # over seconds; over a second or less a drift cannot be told from a vehicle's or a cart's ramp)
        third = (q - p) // 3
        drift = max(tilt_rate * max(0, q - p - third - lean), leak_rate * (q - p - third) if whole else 0.0)
        allowed = math.sqrt(bound2 * own / total) + drift  # issue 31: a whole run may drift as a leak does
        if not third:  # too short to tell: kept as a piece of the run, not as a trimmed end
            if parent is None:
                out.append((p, q, ref, own))
            continue
        first, last = means[p : p + third].mean(axis=0), means[q - third : q].mean(axis=0)
        if parent is not None:
            # cut off a quieter piece beside it: a ramp leaving (or reaching) that rest walks away from its level,
            # a body that settled at a new level (a lean) or sways about it does not. The thirds must hold a
            # window each, or a ramp's start cannot be told from a step (a cart's first 0.2 s of a push)
            near_third, far_third = (first, last) if side > 0 else (last, first)
            away = math.sqrt(np.sum((far_third - parent) ** 2)) - math.sqrt(np.sum((near_third - parent) ** 2))
            if third < w or away > allowed:
                continue
        elif np.sum((first - last) ** 2) > allowed**2:
            continue
        out.append((p, q, ref, own))
    return out


def intervals(mask: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in ``mask`` as (first, last + 1) sample pairs."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
