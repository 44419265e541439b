"""Automatic zero-velocity updates: find candidate rests in the raw acceleration, decide which are rests, turn
them into measurements.

Detector and decision, apart
----------------------------
The detector (:func:`candidates`, below) finds *candidates*: stretches quiet enough to be a rest, each with
its stillness. A moving-variance test on acceleration alone: the accelerometer half of the generalised
likelihood-ratio (GLRT) detectors of Skog et al. (2010, "Zero-velocity detection: an algorithm
evaluation"), whose SHOE detector adds a gyroscope term accelnav does not have. A quiet window cannot tell
a rest from a smooth cruise, a coast or a constant-acceleration hold, so a candidate is only a hypothesis.
The decision (:func:`decide_rests`, accelnav.estimate.rests) accepts one only where a zero velocity agrees
with everything else the record knows: the position fixes, the other accepted rests, the kinematics of a
stop, the model. Its module docstring says how; no accepted rest vouches for the next, and where nothing
can tell, the candidate is refused as "cannot tell" (no update rather than a wrong one). Each decision
carries its reason and, in words, the evidence that decided it (:class:`RestDecision`, :func:`report_csv`).
No threshold hangs on the model's ``initial_sigma`` (issue 23: a tuned model's bias prior admitted
anything); the model's prior on the start speed only says whether a run may be assumed to start at rest.

Candidates (one decision per sample, for the body as a whole)
------------------------------------------------------------
Over a centred window of W = round(window_s * rate) samples (odd, at least 3,
default 0.1 s: a 0.15 s stance still holds several window centres), on the
measured acceleration z_j of every axis minus the model's bias mean:

1. **quiet**: the mean over the axes of window variance / (R_j + tremor^2)
   is at most ``var_k`` (10). The noise of a body at rest is the sensor's R
   plus its own motion, ``tremor`` (0.12 m/s^2 rms: a stance's sway, an idling
   engine). On gaitmap's real walk the stances' windows reach 20 to 150 R, the
   swings' 1e3 to 1e4 R (tests/estimate/test_real_walk.py). On pure noise the statistic
   is chi2(n (W - 1)) / (n (W - 1)) or less (0.1 % quantile 2.3 for W = 11).
2. every sample of the window valid (not clipped, finite) on every axis.

Runs of passing centres are **split into pieces of steady level**: the
longest stretch whose window means stay within ``trim_k`` (3) standard
deviations of a window mean (sqrt((R + tremor^2) / W), or of the run's own
median window variance where a body sways more than that) of the run's median is
one piece, the parts either side are split again; a piece whose first and
last thirds differ by more than their own noise allows, and faster than a
tilt may drift beyond its first second (``level_rate``, 0.1 m/s^2 a second:
a person standing leans that slowly; over a second a drift cannot be told
from a vehicle's or a cart's ramp), is part of a ramp and dropped; a piece that is a whole run, a move
the window sees on both sides (a stance between two swings), may drift at ``leak_rate`` (2 m/s^2 a second:
a jogger's level frame leaks 3 m/s^2 and swings by up to 1.5 m/s^2 a second, 0.3 m/s^2 within one stance).
A part of a run with no window near its median (a long quiet drive under a drifting tilt) is halved and
each half split on its own. The gentle start of a move
is quiet, but its mean walks away from the rest's (a vehicle's, a cart's
first 0.1 m/s^2), and that is where a rest must end; a constant-acceleration
hold becomes a piece of its own (the decision refuses it: its level jumped with no turn between,
or the velocity does not close). Its ends are
trimmed once more against the piece's own measured noise where that is
below the tremor allowance (a parked car, a resting cart). What that trim
cuts off is split again, and a piece of it is kept when it holds three
windows at least (its thirds a window each: shorter, a ramp's start cannot be
told from a step) and its level does not walk away from the rest it was cut
from by more than that noise allows (a ramp leaves a rest's level; a body that
settled at a new level, or sways about it, does not). On mobgap's MS_001/Trial2
the standing's level steps by 0.11 m/s^2 at 1.7 s, with no rotation on the
gyroscope, and stays there; without this its last 0.7 s were lost. Each piece is
widened by up to ``widen`` * (W // 2) samples each side (every sample of a
passing window was quiet), sample by sample while each stays within
``trim_k`` sd of the piece's level (the piece's own per-sample noise): a
heel strike or a ramp's start ends it. Pieces at the same level
less than ``bridge_s`` apart across a break that failed the quiet test are joined (a knock fails every window that
holds it), and pieces shorter than ``min_rest_s`` are dropped.

Measurements: every sample of an accepted rest gets a zero-velocity update
(:func:`accelnav.estimate.kf.zero_velocity`, u = 0 with standard deviation
``sigma``), on every axis (``every_s`` > 0 thins them to one per every_s). The smoother applies them
ungated: the decision already tested each rest whole, against every axis at once.

The thresholds have command-line overrides (``accelnav smooth --zupt-*``); ``passes`` and
``start_within_s`` are the library's alone.
"""

from __future__ import annotations

import contextlib
import gc
import math
import threading
from dataclasses import dataclass

import numpy as np

from accelnav.estimate.kf import Aids, Measurement
from accelnav.estimate.rests import ACCEPT_REASONS, REFUSE_REASONS, Clock, RestDecision, decide
from accelnav.fileio import check_input, excerpt
from accelnav.model.design import axis_design
from accelnav.model.load import G0, Model


@dataclass(frozen=True)
class ZuptParams:
    window_s: float = 0.1  # s, centred window of the moving mean and variance
    var_k: float = 10.0  # quiet if mean over axes of window variance / (R + tremor^2) <= var_k
    tremor: float = 0.12  # m/s^2 rms, the motion of a body at rest (a stance's sway, an idling engine)
    trim_k: float = 3.0  # rest ends trimmed while the window mean is this many sd off the rest's own
    level_rate: float = 0.1  # m/s^3, a candidate's level may drift this fast (a lean), faster is a ramp
    leak_rate: float = 2.0  # m/s^3, ... and a whole quiet run between two moves this fast (a jog's level leak)
    still_k: float = 3.0  # a still start or stand: mean variance <= still_k R (no tremor allowance) ...
    start_s: float = 1.0  # s, ... and lasting this long (a car at a smooth cruise is still for a moment)
    start_within_s: float = 3.0  # s, a still start begins this early at the latest
    min_rest_s: float = 0.1  # s, shortest rest kept (after widening)
    bridge_s: float = 0.1  # s, a break in a rest this short (a knock, a glitch) does not split it
    widen: float = 1.0  # pieces widened by up to widen * (W // 2) samples each side, while samples stay level
    sigma: float = 0.02  # m/s, standard deviation of each zero-velocity update
    every_s: float = 0.0  # s, one update per every_s within a rest; 0: every sample
    gate: float = 12.0  # a side's chi-square of v over the axes, on one axis' scale (12: 3.5 sd); 0: accept all
    drift: float = 0.05  # m/s^2, mean acceleration error between aids that no level explains (a scale factor)
    scale: float = 0.03  # share of the acceleration integrated since the last aid that may be error (a scale factor)
    tell: float = 0.5  # m/s, a side can tell a rest when the sd of its velocity is at most this on every axis
    level_still: float = 0.5  # m/s^2, a rest's level may differ this much from the last rest's with no motion between
    level_max: float = 4.0  # m/s^2, ... and this much after a move (a jog's or a tilting mount's leak)
    level_walk: float = 0.05  # m/s^2 per sqrt(s), the level's random walk between aids (accelnav.estimate.rests)
    rel: float = 0.25  # a still stand: the speed since the last rest came back to at most rel of its peak
    passes: int = 20  # bound on the decision's passes (each: the forward and the backward kinematic filter)


def window_samples(model: Model, p: ZuptParams) -> int:
    w = max(3, int(round(p.window_s * model.rate_hz)))
    return w if w % 2 else w + 1


def resolved(model: Model, p: ZuptParams) -> ZuptParams:
    """``p`` checked (ValueError naming the field); nothing is taken from the model."""
    for name in ("window_s", "var_k", "sigma", "still_k", "tell", "level_walk", "level_still", "level_max"):
        v = getattr(p, name)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"zupt {name}: got {v}; accepted: a number > 0")
    for name in ("every_s", "min_rest_s", "rel", "widen", "bridge_s", "tremor", "trim_k", "level_rate", "leak_rate"):
        v = getattr(p, name)
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"zupt {name}: got {v}; accepted: a number >= 0")
    for name in ("start_s", "start_within_s", "drift", "scale"):
        v = getattr(p, name)
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"zupt {name}: got {v}; accepted: a number >= 0")
    if not (math.isfinite(p.gate) and p.gate >= 0):
        raise ValueError(f"zupt gate: got {p.gate}; accepted: a number >= 0 (0: no gate)")
    if not (isinstance(p.passes, int) and 1 <= p.passes <= 100):
        raise ValueError(f"zupt passes: got {p.passes}; accepted: a whole number 1..100")
    return p


def _windows(x: np.ndarray, usable: np.ndarray, allow: np.ndarray, w: int, var_k: float):
    """(means, wvar, centre) over the centred window of w (odd) samples about each sample: the window mean per axis
    (N, n_axes), the window variance summed over the axes (N,), and the quiet centres (N,) bool: every sample of
    the window ``usable`` (N,) and the mean over axes of variance / ``allow`` at most ``var_k``. NaN (False)
    where the window leaves the run. Every figure whole: the detector holds only the flags
    (:func:`_centres`) and the figures of one run at a time (:class:`_Spans`); tests hold both to this.

    Compiled (acn_rest_centres, acn_rest_span in csrc/fastsmooth.c): in numpy these were a dozen whole-record
    passes (cumsums, differences, temporaries), the largest share of the detector's time. The C differences numpy's
    cumsums in numpy's order, so every figure is the same double (tests/estimate/test_zupt_windows.py holds it to
    the numpy it replaced, kept in tests/support/zupt_oracle.py)."""
    n, n_axes = np.shape(x)
    centre = _centres(x, usable, allow, w, var_k)
    means, wvar = np.full((n, n_axes), np.nan), np.full(n, np.nan)
    h = w // 2
    if n >= w:
        means[h : n - h], wvar[h : n - h] = _Spans(x, w).of(h, n - h)
    return means, wvar, centre


def _centres(x: np.ndarray, usable: np.ndarray, allow: np.ndarray, w: int, var_k: float) -> np.ndarray:
    """The quiet centres of :func:`_windows` (N,) bool, nothing else held a sample."""
    from accelnav.estimate.chunked import fresh_array
    from accelnav.estimate.fastsmooth import _lib

    n, n_axes = x.shape
    mod = _lib()
    ffi = mod.ffi
    xc = np.ascontiguousarray(x, dtype=np.float64)
    usable = np.ascontiguousarray(usable, dtype=bool).view(np.uint8)
    allow = np.ascontiguousarray(allow, dtype=np.float64)
    state, at = np.zeros(4 * n_axes), np.full(n_axes, -1, dtype=np.int64)
    centre = fresh_array((n,), np.uint8)
    if len(allow) != n_axes or len(usable) != n:
        raise ValueError(f"rest detector: {len(allow)} noise figures and {len(usable)} rows for {n} x {n_axes} samples")
    d, u = (lambda a: ffi.from_buffer("double[]", a)), (lambda a: ffi.from_buffer("unsigned char[]", a))
    status = mod.lib.acn_rest_centres(
        n, n_axes, d(xc), u(usable), w, d(allow), float(var_k), d(state), ffi.from_buffer("long[]", at), u(centre)
    )
    if status != 0:
        raise ValueError(
            f"rest detector: a window of {w} samples over {n} x {n_axes}; accepted: an odd window, 1+ axes"
        )
    return centre.view(bool)


class _Spans:
    """The window means (rows, n_axes) and variances summed over axes (rows,) of :func:`_windows` for the centres
    of one span at a time, spans asked in sample order: the sums carried from one span to the next (a few doubles
    an axis), so the same doubles as the whole pass, and only a span's figures held."""

    def __init__(self, x: np.ndarray, w: int) -> None:
        from accelnav.estimate.fastsmooth import _lib

        self.x = np.ascontiguousarray(x, dtype=np.float64)
        self.w = int(w)
        n_axes = self.x.shape[1]
        self.state, self.at = np.zeros(4 * n_axes), np.full(n_axes, -1, dtype=np.int64)
        self.mod = _lib()

    def of(self, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
        n, n_axes = self.x.shape
        means, wvar = np.empty((max(hi - lo, 0), n_axes)), np.empty(max(hi - lo, 0))
        buf = self.mod.ffi.from_buffer
        status = self.mod.lib.acn_rest_span(
            n, n_axes, buf("double[]", self.x), self.w, int(lo), int(hi), buf("double[]", self.state),
            buf("long[]", self.at), buf("double[]", means), buf("double[]", wvar),
        )  # fmt: skip
        if status != 0:
            raise ValueError(
                f"rest detector: centres {lo}..{hi} of {n} x {n_axes} with a window of {self.w}, after "
                f"{self.at.max()}; accepted: windows inside the record, asked in order"
            )
        return means, wvar


def _prepared(accel, clipped, model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, ok, R): acceleration minus the bias mean (0 where unusable), the usable mask, R per axis.

    Compiled past the bias' powers (acn_rest_prepare: the mask, the bias and the difference in one pass per axis,
    numpy's operations in numpy's order, kf.bias_model's formula); the powers stay numpy's own, so x is the same
    double (tests/estimate/test_zupt_windows.py)."""
    accel = np.asarray(accel)
    if np.shape(clipped) != accel.shape:
        raise ValueError(f"rest detector: clipped is {np.shape(clipped)}; accel is {accel.shape}")
    n = len(accel)
    return _prepared_read(lambda s, e: (None, accel[s:e], clipped[s:e]), n, accel.shape[1], model, max(n, 1))


def _prepared_read(read, n: int, n_axes: int, model: Model, chunk: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_prepared` of a record read ``chunk`` rows at a time by ``read(s, e)`` (t, accel, clipped of rows s..e-1,
    an engine.Source's reader): the record is not held whole beside x and ok (26 B a sample at 2 axes). Row by row,
    so the same doubles whatever the chunks."""
    from accelnav.estimate.chunked import fresh_array
    from accelnav.estimate.fastsmooth import _lib

    x = fresh_array((n, n_axes))
    ok = fresh_array((n, n_axes), bool)
    R = np.empty(n_axes)
    mod = _lib()
    buf = mod.ffi.from_buffer
    powers: dict[tuple, np.ndarray] = {}  # phi^k per bias time constant: the axes of a model mostly share one
    axes = []
    for j in range(n_axes):
        d = axis_design(model, j)
        c1, eps_mean = float(d.axis.c1), float(d.eps_mean)
        key = (d.phi, _bias_settled(d.phi, c1, eps_mean, n))
        if key not in powers:
            powers[key] = _bias_powers(d.phi, *key[1:], n)
        axes.append((powers[key], eps_mean, c1))
        R[j] = d.R
    for s in range(0, n, chunk):
        e = min(n, s + chunk)
        _, accel, clipped = read(s, e)
        accel = np.ascontiguousarray(accel, dtype=np.float64)
        clipped = np.ascontiguousarray(clipped, dtype=bool)
        if accel.shape != (e - s, n_axes) or clipped.shape != accel.shape:
            raise ValueError(f"rest detector: rows {s}..{e} read as {accel.shape} and {clipped.shape}")
        a_p, c_p = buf("double[]", accel), buf("unsigned char[]", clipped.view(np.uint8))
        x_p, ok_p = buf("double[]", x[s:e]), buf("unsigned char[]", ok[s:e].view(np.uint8))
        for j, (pw, eps_mean, c1) in enumerate(axes):
            # kf.bias_model's eps[k] = eps_mean - c1 phi^k, taken from the ok samples
            if mod.lib.acn_rest_prepare(e - s, n_axes, j, a_p, c_p, buf("double[]", pw[s:e]), eps_mean, c1, x_p, ok_p):
                raise ValueError(f"rest detector: {n} x {n_axes} samples; accepted: 1+ axes")
    return x, ok, R


def _bias_settled(phi: float, c1: float, eps_mean: float, n: int) -> int:
    """The first sample k (at most n) from which c1 phi^k is below an eighth of eps_mean's spacing: eps_mean - c1 phi^k
    is then eps_mean itself, the same double as with c1 phi^k = 0 (a bias settled to the last bit; at 100 Hz with a
    300 s time constant, after 1.1e6 samples)."""
    if not (0.0 < phi < 1.0) or c1 == 0.0 or not math.isfinite(c1):
        return n if c1 != 0.0 else 0
    tiny = float(np.spacing(abs(eps_mean))) / 8.0 / abs(c1)
    if not tiny > 0.0:
        return n
    k = max(0, math.ceil(math.log(tiny) / math.log(phi)))
    while k < n and float(phi ** np.arange(k, k + 1, dtype=np.int64)[0]) > tiny:  # numpy's power, not the log's
        k += 1
    return min(n, k)


def _bias_powers(phi: float, settled: int, n: int) -> np.ndarray:
    """phi^k for k < n as numpy computes them (phi ** np.arange), 0 from ``settled`` on (:func:`_bias_settled`:
    there they change nothing; numpy's powers of 1e7 samples took 0.5 s an axis, measured)."""
    out = np.zeros(n)
    out[:settled] = phi ** np.arange(settled)
    return out


GRAVITY_TOL = 0.25  # g: an axis whose median reads within this of +-1 g is taken as carrying gravity


def gravity_axes(accel: np.ndarray, clipped: np.ndarray, model: Model) -> list[str]:
    """Names of the axes whose median acceleration (bias removed) is about +-1 g: gravity on them.

    The model takes gravity as removed (a level frame, or the axis held horizontal); a tilt of such an
    axis moves its reading by the whole of g, which the detector sees as motion or a level change. Only
    for the summary: the detector's decisions do not read this."""
    return gravity_of(*_prepared(accel, clipped, model)[:2], model)


def gravity_of(x: np.ndarray, ok: np.ndarray, model: Model) -> list[str]:
    """:func:`gravity_axes` of the prepared record (:func:`_prepared`)."""
    out = []
    for j, ax in enumerate(model.axes):
        if ok[:, j].any() and abs(abs(float(np.median(x[ok[:, j], j]))) - G0) <= GRAVITY_TOL * G0:
            out.append(ax.name)
    return out


def candidates(accel: np.ndarray, clipped: np.ndarray, model: Model, params: ZuptParams = ZuptParams()) -> np.ndarray:
    """(N,) bool: samples the detector calls rest, before the per-rest decision (see the module docstring).

    ``accel``, ``clipped`` are (N, n_axes) as in a run file; columns are the model's axes in order.
    """
    p = resolved(model, params)
    return _detect(*_prepared(accel, clipped, model), model, p)


def _detect(x: np.ndarray, ok: np.ndarray, R: np.ndarray, model: Model, p: ZuptParams) -> np.ndarray:
    """:func:`candidates` on the prepared record (:func:`_prepared`), which the decision reads too."""
    n, n_axes = x.shape
    w = window_samples(model, p)
    usable = ok[:, 0].copy()  # ok.all(axis=1) column by column: numpy's strided all took 0.2 s at 1e7 x 2
    for j in range(1, n_axes):
        usable &= ok[:, j]
    centre = _centres(x, usable, R + p.tremor**2, w, p.var_k)
    spans = _Spans(x, w)  # one run's window figures at a time, not the record's (24 B a sample at 2 axes)
    # split each run into pieces of steady level: a move that starts gently is quiet, but its mean walks away
    total = float(np.sum(R + p.tremor**2))
    bound2 = p.trim_k**2 * total / w
    runs = intervals(centre)
    # a body swaying more than the tremor allowance (a real stance) has a level that wanders as much: the bound
    # grows with the run's own typical window variance (not with a ramp, whose windows stay quiet)
    # (the median reorders the run's variances in place, and the pieces then take that array as their scratch: a
    # long rest's run holds its means and one array besides, not three)
    parts = [
        _steady_pieces(
            means,
            a,
            b,
            bound2 * max(1.0, _median_in_place(wvar) / total),
            x,
            total,
            w,
            p.level_rate * model.Ts,
            int(round(model.rate_hz)),  # a lean is told from a ramp over more than a second
            p.leak_rate * model.Ts,
            scratch=wvar,
        )
        for a, b in runs
        for means, wvar in [spans.of(a, b)]
    ]  # in sample order: runs are, and so are the pieces of each
    # widen each piece towards its windows' extent (every sample of a passing window was quiet), sample by
    # sample while a sample stays within trim_k sd of the piece's level: a heel strike or the start of a ramp
    # ends it. Join pieces at one level across short breaks (a knock fails every window that holds it);
    # pieces at two levels stay apart by a sample at least, so each is judged on its own
    h = int(round(p.widen * (w // 2)))
    bridge = int(round(p.bridge_s * model.rate_hz))
    # the pieces of every run as arrays (a tuple and a row view per piece cost more than the pieces' C at 1e7)
    starts = np.concatenate([q[0] for q in parts]) if parts else np.zeros(0, dtype=np.int64)
    stops = np.concatenate([q[1] for q in parts]) if parts else np.zeros(0, dtype=np.int64)
    refs = np.concatenate([q[2] for q in parts]).reshape(-1, n_axes) if parts else np.zeros((0, n_axes))
    lim2 = p.trim_k**2 * (np.concatenate([q[3] for q in parts]) if parts else np.zeros(0))
    run_of = np.repeat(np.arange(len(parts)), [len(q[0]) for q in parts]).tolist()
    starts = starts - _level_steps(x, usable, refs, lim2, starts, -1, h)
    stops = stops + _level_steps(x, usable, refs, lim2, stops - 1, 1, h)
    # join each piece to the one before it (then to that one's group) across a short knock: a break that failed the
    # quiet test (another run, not a change of level), within the bridge, every sample of the gap usable (not
    # clipped or missing), at one level with the group's first piece. All but the level are the two pieces' own
    # (a group ends where its last piece does), so they are tested as arrays and only the few pieces that pass
    # them walk in order (a loop over every piece cost 0.2-0.4 s at 1e7)
    count = len(starts)
    runs_arr = np.asarray(run_of, dtype=np.int64)
    joins = np.zeros(count, dtype=bool)
    if count > 1:
        joins[1:] = (runs_arr[1:] != runs_arr[:-1]) & (starts[1:] - stops[:-1] <= bridge)
    group = np.arange(count)  # the first piece of each piece's group, for the few that may join
    for i in np.flatnonzero(joins).tolist():
        g = int(group[i - 1])
        joins[i] = bool(np.sum((refs[i] - refs[g]) ** 2) <= bound2) and bool(usable[stops[i - 1] : starts[i]].all())
        if joins[i]:
            group[i] = g
    firsts = np.flatnonzero(~joins)
    lasts = np.append(firsts[1:] - 1, count - 1) if count else firsts
    a_of = starts[firsts]
    if len(firsts) > 1:  # a group after another starts a sample past it at least: each is judged on its own
        a_of[1:] = np.maximum(a_of[1:], stops[firsts[1:] - 1] + 1)
    b_of = stops[lasts]
    shortest = max(1, int(round(p.min_rest_s * model.rate_hz)))
    mask = np.zeros(n, dtype=bool)
    keep = b_of - a_of >= shortest
    for a, b in zip(a_of[keep].tolist(), b_of[keep].tolist(), strict=True):  # a slice per rest (tens of thousands)
        mask[a:b] = True
    return mask


def _median_in_place(v: np.ndarray) -> float:
    """np.median(v) (the same double: an order statistic, or the mean of the two middle ones), ``v`` reordered.
    Compiled (acn_rest_median): numpy's partition and mean per run took 0.2-0.4 s CPU over the 1 105 runs of 1e7."""
    from accelnav.estimate.fastsmooth import _lib

    if not (v.dtype == np.float64 and v.ndim == 1 and v.flags.c_contiguous and v.flags.writeable):
        raise ValueError("rest detector: a median of a writable contiguous float64 vector only")
    mod = _lib()
    return float(mod.lib.acn_rest_median(len(v), mod.ffi.from_buffer("double[]", v)))


def _level_steps(
    x: np.ndarray, usable: np.ndarray, refs: np.ndarray, lim2: np.ndarray, edge: np.ndarray, step: int, h: int
) -> np.ndarray:
    """Per piece, how many samples past its ``edge`` sample (walking by ``step``, -1 or 1, at most h, not off
    the run) stay usable and within sqrt(lim2) of the piece's level ``refs`` before the first that does not:
    the widening of every piece at once.

    Compiled (acn_rest_widen): numpy's gathers of every piece's h samples took 0.14 s at 1e7 (twice); the C sums
    the squares over the axes in order, as numpy does for up to 7 (:data:`_MAX_AXES`)."""
    from accelnav.estimate.fastsmooth import _lib

    n, n_axes = x.shape
    count = len(edge)
    if h < 1 or not count:
        return np.zeros(count, dtype=np.int64)
    if n_axes > _MAX_AXES:
        raise ValueError(f"rest detector: {n_axes} axes; accepted: at most {_MAX_AXES}")
    xc = np.ascontiguousarray(x, dtype=np.float64)
    ok = np.ascontiguousarray(usable, dtype=bool).view(np.uint8)
    refs = np.ascontiguousarray(refs, dtype=np.float64)
    lim2 = np.ascontiguousarray(lim2, dtype=np.float64)
    edge = np.ascontiguousarray(edge, dtype=np.int64)
    if ok.shape != (n,) or refs.shape != (count, n_axes) or lim2.shape != (count,):
        raise ValueError(
            f"rest detector: usable {ok.shape}, levels {refs.shape}, bounds {lim2.shape} for {count} pieces"
        )
    out = np.empty(count, dtype=np.int64)
    mod = _lib()
    buf = mod.ffi.from_buffer
    status = mod.lib.acn_rest_widen(
        n, n_axes, buf("double[]", xc), buf("unsigned char[]", ok), count, buf("double[]", refs),
        buf("double[]", lim2), buf("long[]", edge), int(step), int(h), buf("long[]", out),
    )  # fmt: skip
    if status != 0:
        raise ValueError(
            f"rest detector: widening by {step} from {count} edges over {n} x {n_axes}; accepted: a step"
            " of -1 or 1 from edges within -1..n"
        )
    return out


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
    leak_rate: float = 0.0,
    scratch: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Split the run [a, b) of window centres into pieces whose window means stay within sqrt(bound2) of the
    piece's median: the longest such stretch about the run's median is kept, the parts either side are split
    again; a part with no window near its median (a long quiet drive whose level a drifting tilt spread wide)
    is halved, each half split on its own. The ends of a piece are trimmed again with the bound scaled to the
    piece's own variance (of ``x``, summed over axes, against ``total``, the sum of R + tremor^2) when that is
    smaller; a piece whose first
    and last thirds differ by more than trim_k sd of a window mean (from the piece's own variance) plus
    ``tilt_rate`` (m/s^2 per sample) times their distance beyond ``lean`` samples is a stretch of a ramp
    and dropped (the level moving across it no faster than a tilt may, over more than ``lean`` samples, is a
    lean: a person standing leans over seconds; over a second or less a drift cannot be told from a
    vehicle's or a cart's ramp). A piece that is the whole run, motion on both sides (a stance between two
    swings), may drift at ``leak_rate`` (m/s^2 per sample) over their whole distance instead: a jogger's level
    frame leaks 3 m/s^2 that swings by 1.5 m/s^2 a second; a rest that runs into a gentle ramp is one quiet
    run and keeps the tilt's rate, and the decision tests every candidate against the kinematics besides.
    What the trim cuts off is split again (a standing whose level stepped, by
    0.1 m/s^2 on a real lower-back recording, keeps its second level as a piece of its own); a piece from it
    is kept when it holds three windows at least (thirds of a window each: shorter, a ramp's start cannot be
    told from a step) and its level does not walk away from the piece it was cut from (a ramp leaving a
    rest does; a body that settled at a new level, or sways about it, does not).
    ``means`` are the window means of the run's centres alone (b - a rows, :class:`_Spans`). ``scratch``: b - a
    float64 the kernel may overwrite (a fresh array when None).
    Returns the pieces' (first, last + 1, median level, own variance) as four arrays, in sample order.

    Compiled (acn_rest_pieces in csrc/fastsmooth.c): a ramp is cut into pieces of a sample or two, tens of
    thousands per million samples, each a few array calls in Python. The C takes numpy's steps in numpy's
    order, so the pieces are the same numbers (tests/estimate/test_zupt_arrays.py holds it to the Python
    this replaced)."""
    from accelnav.estimate.fastsmooth import _lib

    n_axes = means.shape[1]
    if n_axes > _MAX_AXES:
        raise ValueError(f"rest detector: {n_axes} axes; accepted: at most {_MAX_AXES}")
    m = b - a
    mod = _lib()
    ffi = mod.ffi
    mc = np.ascontiguousarray(means, dtype=np.float64)
    xc = np.ascontiguousarray(x[a:b], dtype=np.float64)
    start, stop = np.empty(max(m, 1), dtype=np.int64), np.empty(max(m, 1), dtype=np.int64)
    ref, own = np.empty((max(m, 1), n_axes)), np.empty(max(m, 1))
    if scratch is None:
        scratch = np.empty(max(m, 1))
    if not (scratch.dtype == np.float64 and scratch.flags.c_contiguous and scratch.flags.writeable):
        raise ValueError("rest detector: the pieces' scratch must be a writable contiguous float64 array")
    if scratch.ndim != 1 or len(scratch) < m or mc.shape != (m, n_axes) or xc.shape != (m, n_axes):
        raise ValueError(f"rest detector: {len(scratch)} scratch rows, means {mc.shape}, x {xc.shape} for run {a}..{b}")
    count = mod.lib.acn_rest_pieces(
        m, n_axes, ffi.from_buffer("double[]", mc), ffi.from_buffer("double[]", xc), bound2, total, w,
        tilt_rate, lean, leak_rate, ffi.from_buffer("double[]", scratch), ffi.from_buffer("long[]", start),
        ffi.from_buffer("long[]", stop), ffi.from_buffer("double[]", ref), ffi.from_buffer("double[]", own),
    )  # fmt: skip
    if count < 0:
        raise MemoryError("rest detector: no memory for a run's pieces")
    order = np.argsort(start[:count], kind="stable")
    return a + start[order], a + stop[order], ref[order], own[order]


_MAX_AXES = 7  # acn_rest_pieces sums over the axes in order, as numpy does up to 7 terms (from 8 numpy's sums are
# pairwise, measured: the same figures would not be numpy's). Models take 1 to 3 axes


def gate_rests(
    accel: np.ndarray,
    clipped: np.ndarray,
    rest: np.ndarray,
    model: Model,
    params: ZuptParams = ZuptParams(),
    fixes: list[list[Measurement]] | None = None,
) -> list[RestDecision]:
    """Decide once per candidate rest of ``rest`` (:func:`candidates`), for all axes together, against the
    fixes (per axis column, accelnav.estimate.fixes.read_fixes) and the other rests: accelnav.estimate.rests."""
    return decide_rests(accel, clipped, rest, model, params, fixes).decisions


@dataclass(frozen=True)
class Rests:
    """The detector's candidates, the decision on each, and what the CLI reports of them."""

    candidates: np.ndarray  # (N,) bool
    decisions: list[RestDecision]
    mask: np.ndarray  # (N,) bool, the samples of the accepted rests


def decide_rests(
    accel: np.ndarray,
    clipped: np.ndarray,
    rest: np.ndarray | None,
    model: Model,
    params: ZuptParams = ZuptParams(),
    fixes: list[list[Measurement]] | None = None,
) -> Rests:
    """Candidates (``rest``, or :func:`candidates` when None) and the decision on each (accelnav.estimate.rests).

    Python's cycle collector is held off meanwhile: the pieces, events, sides and verdicts of a long record are
    hundreds of thousands of small objects, none in a cycle that must go before the end, and each full collection
    walked all of them (0.5-1 s CPU of 8-9 at 1e7 samples, measured). The caller's own setting comes back however
    the decision ends (:func:`collector_held`)."""
    with collector_held():
        p = resolved(model, params)
        return _decided(*_prepared(accel, clipped, model), rest, model, p, fixes)


def decide_rests_read(read, n: int, n_axes: int, rest: np.ndarray | None, model: Model,
                      params: ZuptParams = ZuptParams(), fixes=None, *, chunk: int = 1 << 20) -> Rests:  # fmt: skip
    """:func:`decide_rests` of a record read ``chunk`` rows at a time by ``read(s, e)`` (t, accel, clipped;
    engine.Source's reader): the same decisions, the record not held whole."""
    with collector_held():
        p = resolved(model, params)
        return _decided(*_prepared_read(read, n, n_axes, model, max(int(chunk), 1)), rest, model, p, fixes)


def gravity_axes_read(read, n: int, n_axes: int, model: Model, *, chunk: int = 1 << 20) -> list[str]:
    """:func:`gravity_axes` of a record read ``chunk`` rows at a time (:func:`decide_rests_read`)."""
    return gravity_of(*_prepared_read(read, n, n_axes, model, max(int(chunk), 1))[:2], model)


def _decided(x, ok, R, rest, model: Model, p: ZuptParams, fixes) -> Rests:
    """The detector (unless ``rest`` gives the candidates) and the decision on the prepared record, which both read."""
    if rest is None:
        rest = _detect(x, ok, R, model, p)
    t = Clock(len(x), model.Ts)  # the record's times where the words name them, not an array of them
    # the model's own prior on the start speed: a model that says the run may start moving is not overruled
    start_sd = max(float(np.sqrt(axis_design(model, j).P0[1, 1])) for j in range(x.shape[1]))
    decisions = decide(x, ok, R, model.Ts, t, intervals(rest), fixes, p, start_sd)
    return Rests(np.asarray(rest, dtype=bool), decisions, accepted_mask(decisions, len(rest)))


_held = {"count": 0, "was": False}  # decisions holding the collector off now, and its setting before the first
_held_lock = threading.Lock()


@contextlib.contextmanager
def collector_held():
    """Python's cycle collector off within, process-wide (the collector has no per-thread switch): the setting the
    process had before the first of the decisions holding it comes back when the last of them ends, by return or by
    exception. Two threads deciding at once: the first to end does not turn it back on under the other, the other
    does not leave it off."""
    with _held_lock:
        if _held["count"] == 0:
            _held["was"] = gc.isenabled()
            gc.disable()
        _held["count"] += 1
    try:
        yield
    finally:
        with _held_lock:
            _held["count"] -= 1
            if _held["count"] == 0 and _held["was"]:
                gc.enable()


def reason_counts(decisions: list[RestDecision]) -> dict[str, int]:
    """How many candidates each reason decided, accepted reasons first, in a fixed order; zero counts left out."""
    counts = {r: 0 for r in (*ACCEPT_REASONS, *REFUSE_REASONS)}
    for d in decisions:
        counts[d.reason] += 1
    return {r: c for r, c in counts.items() if c}


REPORT_COLUMNS = (
    "start_s", "end_s", "samples", "decision", "reason", "evidence", "still_R", "level_m_s2", "v_before_m_s",
    "sd_before_m_s", "v_after_m_s", "sd_after_m_s", "chi2",
)  # fmt: skip


def report_csv(decisions: list[RestDecision], t: np.ndarray) -> str:
    """One CSV row per candidate: times, samples, decision, reason, the evidence in words and the statistics
    it rests on (``smooth --zupt-report``). ``t``: the run's times, or a function giving them at samples (a run
    not held whole: engine.Source.times_at)."""
    import csv
    import io

    if callable(t):
        at = np.array([k for d in decisions for k in (d.start, d.stop - 1)], dtype=np.int64)
        t = dict(zip(at.tolist(), np.asarray(t(at), dtype=np.float64), strict=True))
    else:
        t = np.asarray(t, dtype=np.float64)

    def f(v: float) -> str:
        return "" if not math.isfinite(v) else f"{v:.6g}"

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(REPORT_COLUMNS)
    for d in decisions:
        w.writerow(
            [f"{t[d.start]:.6f}", f"{t[d.stop - 1]:.6f}", d.stop - d.start, "accepted" if d.accepted else "refused",
             d.reason, d.evidence, f(d.still), f(d.level), f(d.v_before), f(d.sd_before), f(d.v_after),
             f(d.sd_after), f(d.chi2)]
        )  # fmt: skip
    return buf.getvalue()


def rest_mask(
    accel: np.ndarray,
    clipped: np.ndarray,
    model: Model,
    params: ZuptParams = ZuptParams(),
    fixes: list[list[Measurement]] | None = None,
) -> np.ndarray:
    """(N,) bool: samples of the accepted rests (the detector's candidates, then the decision)."""
    return decide_rests(accel, clipped, None, model, params, fixes).mask


def accepted_mask(decisions: list[RestDecision], n: int) -> np.ndarray:
    """(N,) bool: the samples of the accepted rests; two accepted rests one sample apart (the sample that keeps
    two pieces at two levels apart, :func:`candidates`) are one rest."""
    mask = np.zeros(n, dtype=bool)
    last = None
    for d in decisions:
        if d.accepted:
            start = last if last is not None and d.start - last <= 1 else d.start
            mask[start : d.stop] = True
            last = d.stop
    return mask


def intervals(mask: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in ``mask`` as (first, last + 1) sample pairs."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def update_samples(mask: np.ndarray, model: Model, params: ZuptParams = ZuptParams()) -> np.ndarray:
    """Sample indices that get a zero-velocity update: every sample of each rest run, or every every_s seconds
    (counted from each rest's first sample): :meth:`RestSpans.updates` over the whole (N,) ``mask``."""
    m = np.asarray(mask, dtype=bool).reshape(-1)
    return RestSpans.of_mask(m).updates(0, 0, len(m), model, params)[0]


def measurements(ks: np.ndarray, params: ZuptParams = ZuptParams()) -> tuple[list[Measurement], list[float]]:
    """Zero-velocity updates at samples ``ks`` and their gates (for accelnav.estimate.fastsmooth.smooth)."""
    extras = Aids.zero_velocity(ks, params.sigma).measurements()
    return extras, [params.gate] * len(extras)


def axis_aids(rest: np.ndarray, sigma: np.ndarray | None, model: Model, params: ZuptParams = ZuptParams()) -> Aids:
    """The zero-velocity updates of one axis as arrays: at the samples of its (N,) rest mask that get one
    (:func:`update_samples`), with the per-sample ``sigma`` of a ZUPT file where it gives one (NaN or None:
    ``params.sigma``). One implementation with the chunked runs': :meth:`RestSpans.updates` over every sample."""
    m = np.asarray(rest, dtype=bool).reshape(-1)
    sig = None if sigma is None else np.asarray(sigma, dtype=np.float64).reshape(-1, 1)
    ks, sd = RestSpans.of_mask(m, sig).updates(0, 0, len(m), model, params)
    return Aids.zero_velocity(ks, sd)


def axis_updates(
    rest: np.ndarray, sigma: np.ndarray | None, model: Model, params: ZuptParams = ZuptParams()
) -> tuple[np.ndarray, list[Measurement]]:
    """:func:`axis_aids` as (samples, one :class:`Measurement` each), for callers that mix them with fixes."""
    a = axis_aids(rest, sigma, model, params)
    return a.k, a.measurements()


MAX_SPANS = 1 << 23  # separate rests per axis a rest file may give (24 B each in memory: 200 MB)
_PIECE = 1 << 20  # samples of an NPZ rest mask read at a time


@dataclass(frozen=True)
class RestSpans:
    """Given rests as runs of samples per axis, never a per-sample array (a run of 1e8 samples): axis j rests at
    samples ``lo[j][i] .. hi[j][i] - 1`` (disjoint, ascending), its updates' standard deviation there ``sd[j][i]``
    (NaN: ``--zupt-sigma``). Two runs that touch (``hi == lo``) are one rest with two sigmas."""

    n: int
    lo: tuple[np.ndarray, ...]
    hi: tuple[np.ndarray, ...]
    sd: tuple[np.ndarray, ...]

    @classmethod
    def of_mask(cls, mask: np.ndarray, sigma: np.ndarray | None = None, n_axes: int | None = None) -> RestSpans:
        """The spans of an (N,) or (N, n_axes) ``mask`` with an optional per-sample ``sigma`` of the same shape."""
        m = np.asarray(mask, dtype=bool)
        m = m[:, None] if m.ndim == 1 else m
        sig = None if sigma is None else np.asarray(sigma, dtype=np.float64).reshape(len(m), -1)
        b = _SpanBuilder(m.shape[1] if n_axes is None else n_axes, "the rest mask")
        b.add(0, m, sig)
        return b.done(len(m))

    def __len__(self) -> int:
        return len(self.lo)

    def count(self, j: int, model: Model, params: ZuptParams) -> int:
        """Axis j's zero-velocity updates over the run (:meth:`updates`' count, none made): every sample of a rest,
        or one per every_s from each rest's start (runs that touch are one rest)."""
        lo, hi = self.lo[j], self.hi[j]
        step = max(1, int(round(params.every_s * model.rate_hz)))
        if step == 1:
            return int(np.sum(hi - lo))
        starts, ends, _ = self.rests(j)
        return int(np.sum(-(-(ends - starts) // step)))

    def rests(self, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Axis j's rests (:meth:`rest_of`: touching spans are one): each one's first sample, its last + 1 and its
        id, the index of its first span."""
        lo, hi = self.lo[j], self.hi[j]
        new = self.rest_of(j) == np.arange(len(lo))
        last = np.ones(len(lo), dtype=bool)
        last[:-1] = new[1:]
        return lo[new], hi[last], np.flatnonzero(new)

    def rest_of(self, j: int) -> np.ndarray:
        """Each of axis j's spans' rest, as the index of its first span: spans that touch (one ending where the
        next starts: two sigmas in one rest) are one rest, its updates counted and its NIS told from its start."""
        lo, hi = self.lo[j], self.hi[j]
        new = np.ones(len(lo), dtype=bool)
        new[1:] = lo[1:] != hi[:-1]
        return np.maximum.accumulate(np.where(new, np.arange(len(lo)), 0))

    def updates(self, j: int, s: int, e: int, model: Model, params: ZuptParams) -> tuple[np.ndarray, np.ndarray]:
        """(samples, standard deviations) of axis j's zero-velocity updates in samples s..e-1: those
        :func:`axis_aids` gives the whole run, made for these samples alone. The deviations are one a sample,
        or one (a 0-d array) for all when none of these spans gives its own (detected rests: ``params.sigma``;
        the callers broadcast it), rather than a sample's span looked up for each of millions."""
        lo, hi, sd = self.lo[j], self.hi[j], self.sd[j]
        i0, i1 = int(np.searchsorted(hi, s, side="right")), int(np.searchsorted(lo, e, side="left"))
        a, b = np.maximum(lo[i0:i1], s), np.minimum(hi[i0:i1], e)
        lens = np.maximum(b - a, 0)
        ks = np.repeat(a - (np.cumsum(lens) - lens), lens).astype(np.int64, copy=False)
        ks += np.arange(len(ks), dtype=np.int64)  # in place: a temporary of millions the less
        step = max(1, int(round(params.every_s * model.rate_hz)))
        own = bool(np.isfinite(sd[i0:i1]).any())
        seg = np.repeat(np.arange(i0, i1), lens) if own or (step > 1 and len(ks)) else None
        if step > 1 and len(ks):  # counted from the start of each rest (touching runs are one rest)
            first = lo[self.rest_of(j)]
            keep = (ks - first[seg]) % step == 0
            ks, seg = ks[keep], seg[keep]
        if not own:
            return ks, np.asarray(float(params.sigma))
        given = sd[seg]
        return ks, np.where(np.isfinite(given), given, float(params.sigma))

    def painted(self) -> tuple[np.ndarray, np.ndarray]:
        """((N, n_axes) mask, (N, n_axes) sigma, NaN where none given): the per-sample form, for a run in memory."""
        mask = np.zeros((self.n, len(self)), dtype=bool)
        sig = np.full((self.n, len(self)), np.nan)
        for j, (lo, hi, sd) in enumerate(zip(self.lo, self.hi, self.sd, strict=True)):
            at = np.zeros(self.n + 1, dtype=np.int64)  # disjoint runs: +(i+1) at each start, -(i+1) at each end
            np.add.at(at, lo, np.arange(1, len(lo) + 1))
            np.add.at(at, hi, -np.arange(1, len(lo) + 1))
            seg = np.cumsum(at[:-1]) - 1
            mask[:, j] = seg >= 0
            sig[:, j] = np.where(seg >= 0, sd[np.maximum(seg, 0)] if len(sd) else np.nan, np.nan)
        return mask, sig


class _SpanBuilder:
    """Spans of a per-sample mask (and sigma) given a block of samples at a time, in order."""

    def __init__(self, n_axes: int, src: str) -> None:
        self.src = src
        self.prev = np.zeros(n_axes, dtype=bool)
        self.prev_sd = np.full(n_axes, np.nan)
        self.lo: list[list[np.ndarray]] = [[] for _ in range(n_axes)]
        self.hi: list[list[np.ndarray]] = [[] for _ in range(n_axes)]
        self.sd: list[list[np.ndarray]] = [[] for _ in range(n_axes)]
        self.count = np.zeros(n_axes, dtype=np.int64)

    def add(self, s: int, m: np.ndarray, sig: np.ndarray | None) -> None:
        """Samples s.. of an (k, 1) or (k, n_axes) mask (a column for every axis when one) and sigma."""
        if not len(m):
            return
        for j in range(len(self.prev)):
            col = m[:, j if m.shape[1] > 1 else 0]
            pm = np.concatenate(([self.prev[j]], col[:-1]))
            change = col != pm
            if sig is not None:
                sc = sig[:, j if sig.shape[1] > 1 else 0]
                ps = np.concatenate(([self.prev_sd[j]], sc[:-1]))
                change |= col & pm & ~((sc == ps) | (np.isnan(sc) & np.isnan(ps)))
                self.prev_sd[j] = sc[-1]
            q = np.flatnonzero(change)
            opens, closes = q[col[q]], q[pm[q]]
            self.lo[j].append(s + opens)
            self.hi[j].append(s + closes)
            self.sd[j].append(sc[opens] if sig is not None else np.full(len(opens), np.nan))
            self.prev[j] = col[-1]
            self.count[j] += len(opens)
            if self.count[j] > MAX_SPANS:
                from accelnav.errors import UserError

                raise UserError(f"{self.src}: more than {MAX_SPANS} separate rests on one axis; accepted: that many")

    def done(self, n: int) -> RestSpans:
        def cat(parts, dtype):
            return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype=dtype)

        his = [cat(h + ([np.array([n])] if p else []), np.int64) for h, p in zip(self.hi, self.prev, strict=True)]
        return RestSpans(n, tuple(cat(x, np.int64) for x in self.lo), tuple(his),
                         tuple(cat(x, np.float64) for x in self.sd))  # fmt: skip


def read_zupt_file(path, t: np.ndarray, axis_names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Zero-velocity updates given by the user: ((N, n_axes) bool mask, (N, n_axes) sigma [m/s], NaN = default),
    as :func:`read_rest_spans` reads them, painted per sample (t in any order)."""
    from accelnav.estimate.fixes import Clock

    t = np.asarray(t, dtype=np.float64)
    order = None
    if len(t) > 1 and not np.all(t[1:] >= t[:-1]):  # not sorted (or NaN): work on a sorted copy, mapped back
        order = np.argsort(t, kind="stable")
        t = t[order]
    mask, sig = read_rest_spans(path, Clock(len(t), lambda s, e: t[s:e]), axis_names, _checked=False).painted()
    if order is not None:
        mask[order], sig[order] = mask.copy(), sig.copy()
    return mask, sig


def rest_file_kind(path) -> str:
    """ "npz", "mask" (a CSV of one 0/1 row per sample) or "intervals": the form of a rest file, by content."""
    from accelnav.errors import UserError

    check_input(path)  # a FIFO or a device is refused before it is read
    try:
        with open(path, "rb") as fh:
            head = fh.read(2)
        if head == b"PK":
            return "npz"
        with open(path, encoding="utf-8", errors="replace") as fh:
            first = fh.readline().strip().replace(" ", "")
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror}") from None
    return "mask" if first in ("rest", "t_s,rest", "t,rest") else "intervals"


def read_rest_spans(path, clock, axis_names: list[str], *, _checked: bool = True) -> RestSpans:
    """Zero-velocity updates given by the user, as :class:`RestSpans` on the run's increasing ``clock``
    (accelnav.estimate.fixes.Clock, read a piece at a time). Two forms, told apart by content:

    * **intervals**, CSV with columns ``start_s,end_s`` (inclusive, on the run's
      clock), and optionally ``axis`` (an axis name of the run; without it
      the interval holds for every axis) and ``sigma`` (m/s, the updates'
      standard deviation there; default ``--zupt-sigma``); where intervals overlap, the later row's sigma;
    * **per-sample mask**: an NPZ with a 0/1 array ``rest`` of N samples (or
      (N, n_axes)), read a piece at a time, or a CSV with a header ``rest`` (optionally ``t_s,rest``)
      and one 0/1 row per sample of the run.
    """
    from accelnav.estimate.fixes import read_table

    n, n_axes, src = clock.n, len(axis_names), str(path)
    kind = rest_file_kind(path)
    if kind == "npz":
        return _npz_spans(path, n, n_axes, src)
    if kind == "mask":
        rows = read_table(path, required=("rest",), optional=("t_s", "t"))
        b = _SpanBuilder(n_axes, src)
        b.add(0, _mask_from(np.asarray(rows["rest"]), n, n_axes, src), None)
        return b.done(n)
    rows = read_table(path, required=("start_s", "end_s"), optional=("axis", "sigma"))
    return _interval_spans(rows, clock, axis_names, src, _checked)


def _npz_spans(path, n: int, n_axes: int, src: str) -> RestSpans:
    """The ``rest`` member of an NPZ read a piece at a time (stored or deflated), checked as :func:`_mask_from`."""
    import zipfile

    from numpy.lib import format as npy

    from accelnav.errors import UserError

    try:
        with zipfile.ZipFile(path) as zf:
            names = [i.filename for i in zf.infolist()]
            if "rest.npy" not in names:
                keys = ", ".join(x.removesuffix(".npy") for x in names)
                raise UserError(f"{src}: no 'rest' array; keys: {excerpt(keys) if keys else 'none'}")
            with zf.open("rest.npy") as fh:
                version = npy.read_magic(fh)
                header = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
                shape, fortran, dtype = header(fh)
                if dtype.hasobject or fortran or len(shape) not in (1, 2):
                    raise UserError(f"{src}: 'rest' is not a plain 0/1 array of the run's samples")
                if shape[0] != n or (len(shape) == 2 and shape[1] not in (1, n_axes)):
                    raise UserError(f"{src}: the rest mask has {shape[0]} samples; the run has {n} (and {n_axes} axes)")
                width = 1 if len(shape) == 1 else shape[1]
                b = _SpanBuilder(n_axes, src)
                for s in range(0, n, _PIECE):
                    k = min(_PIECE, n - s)
                    raw = fh.read(k * width * dtype.itemsize)
                    if len(raw) != k * width * dtype.itemsize:
                        raise UserError(f"{src}: the 'rest' array ends early: the file is damaged")
                    m = np.frombuffer(raw, dtype=dtype).reshape(k, width)
                    ok = (m == 0) | (m == 1)
                    if not ok.all():
                        bad = int(np.argmax(~ok.all(axis=1)))
                        raise UserError(f"{src}: rest mask sample {s + bad}: {m[bad].tolist()}; accepted: 0 or 1")
                    b.add(s, m.astype(bool), None)
    except UserError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, ValueError, OSError) as exc:
        raise UserError(f"{src}: damaged NPZ: {excerpt(str(exc))}") from None
    return b.done(n)


def _interval_spans(rows: dict, clock, axis_names: list[str], src: str, checked: bool = True) -> RestSpans:
    """The spans of interval rows in O(N + K log K) for N samples and K intervals: each interval becomes a range of
    samples by one counting pass over the clock, and each sample takes the last row that covers it (a later
    row's sigma wins where intervals overlap, as row-by-row painting gives)."""
    from accelnav.errors import UserError

    n, n_axes = clock.n, len(axis_names)
    a, b = np.asarray(rows["start_s"], dtype=np.float64), np.asarray(rows["end_s"], dtype=np.float64)
    k = len(a)
    axis = np.full(k, -1, dtype=np.int64)  # -1: every axis
    unknown = np.zeros(k, dtype=bool)
    if "axis" in rows:
        names: dict[str, int] = {}
        for j, name in enumerate(axis_names):
            names.setdefault(name, j)  # a repeated name means its first axis (list.index)
        axis = np.array([names.get(ax, -2) for ax in rows["axis"]], dtype=np.int64)
        unknown = axis == -2
    sd = np.asarray(rows["sigma"], dtype=np.float64) if "sigma" in rows else None
    bad_sd = ~(sd > 0) if sd is not None else np.zeros(k, dtype=bool)
    backwards = ~(b >= a)
    if (backwards | unknown | bad_sd).any():  # the first bad row, its first fault, in the order they are checked
        i = int(np.argmax(backwards | unknown | bad_sd))
        if backwards[i]:
            raise UserError(f"{src}: row {i + 2}: end_s {b[i]:g} is before start_s {a[i]:g}")
        if unknown[i]:
            raise UserError(f"{src}: row {i + 2}: axis {rows['axis'][i]!r}; accepted: {', '.join(axis_names)}")
        raise UserError(f"{src}: row {i + 2}: sigma is {sd[i]:g}; accepted: a standard deviation > 0 (m/s)")
    # the first sample with t >= start; past the last sample with t <= end (``checked``: the clock is read a piece
    # at a time and must increase; else an array in memory, sorted by the caller, NaN last as searchsorted takes it)
    lo, _, _, hi, _, _ = clock.place(a, b) if checked else _place_unchecked(clock, a, b)
    los, his, sds = [], [], []
    for j in range(n_axes):
        mine = np.flatnonzero(((axis == -1) | (axis == j)) & (hi > lo))
        bounds, best = _last_cover(lo[mine], hi[mine], n)
        on = best >= 0
        los.append(bounds[:-1][on].astype(np.int64))
        his.append(bounds[1:][on].astype(np.int64))
        sds.append(sd[mine][best[on]] if sd is not None else np.full(int(on.sum()), np.nan))
    return RestSpans(n, tuple(los), tuple(his), tuple(sds))


def _place_unchecked(clock, a: np.ndarray, b: np.ndarray):
    t = clock.read(0, clock.n)
    return np.searchsorted(t, a, side="left"), None, None, np.searchsorted(t, b, side="right"), None, None


def _last_cover(lo: np.ndarray, hi: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(bounds, best): samples bounds[i] .. bounds[i+1] - 1 are covered last by the range [lo, hi) number best[i]
    (-1: none). The answer is constant between consecutive range ends: one heap sweep over those (2K + 1)."""
    import heapq

    bounds = np.unique(np.concatenate(([0, n], lo, hi)))
    best = np.full(len(bounds) - 1, -1, dtype=np.int64)
    by_start = np.argsort(lo, kind="stable")
    heap: list[int] = []  # -index: the latest row on top
    p = 0
    for s, at in enumerate(bounds[:-1].tolist()):
        while p < len(by_start) and lo[by_start[p]] == at:
            heapq.heappush(heap, -int(by_start[p]))
            p += 1
        while heap and hi[-heap[0]] <= at:
            heapq.heappop(heap)
        if heap:
            best[s] = -heap[0]
    return bounds, best


def _mask_from(m: np.ndarray, n: int, n_axes: int, src: str) -> np.ndarray:
    from accelnav.errors import UserError

    if m.ndim == 1:
        m = m[:, None]
    if m.shape[0] != n or m.shape[1] not in (1, n_axes):
        raise UserError(f"{src}: the rest mask has {m.shape[0]} samples; the run has {n} (and {n_axes} axes)")
    if not np.all((m == 0) | (m == 1)):
        bad = int(np.argmax(~((m == 0) | (m == 1)).all(axis=1)))
        raise UserError(f"{src}: rest mask sample {bad}: {m[bad].tolist()}; accepted: 0 or 1")
    return np.broadcast_to(m.astype(bool), (n, n_axes)).copy()
