"""Automatic zero-velocity updates: find the rests in the raw acceleration, turn them into measurements.

Which detector, and why
-----------------------
A moving-variance and magnitude test on acceleration alone: the accelerometer
half of the generalised likelihood-ratio (GLRT) detectors of Skog et al.
(2010, "Zero-velocity detection: an algorithm evaluation"), whose SHOE
detector adds a gyroscope term accelnav does not have. For a sample window
the GLRT of "the body is at rest" against "it moves" compares the readings
with what a rest predicts; with the rest's acceleration unknown in direction
(gravity leaking through a tilt error, an unmodelled bias) the accelerometer
term becomes the spread of the window about its own mean (the MV detector),
and a rest of a horizontal, gravity-removed axis must also read near zero
(the MAG detector's role). One short window serves a car that waits for
seconds and a foot whose stance lasts a quarter of a second, because both
tests are normalised by the sensor's own noise R rather than tuned to a
motion.

The detector (one decision per sample, for the body as a whole)
----------------------------------------------------------------
Over a centred window of W = round(window_s * rate) samples (odd, at least 3,
default 0.1 s: a 0.25 s stance still holds 15 window centres), on the
measured acceleration z_j of every axis j minus the model's bias mean
eps_j(k) = (c1 + c2) - c1 phi^k:

1. **quiet**: the mean over the axes of window variance / (R_j + tremor^2)
   is at most ``var_k`` (default 10). The rest hypothesis's noise is the
   sensor's R plus the motion of a body at rest, ``tremor`` (default
   0.12 m/s^2 rms): a foot in stance sways, an engine idles, and on a good
   sensor that motion, not the sensor, sets the floor. On gaitmap's real
   foot-mounted walk (204.8 Hz, R = 1.4e-3) the stances' windows reach 20 to
   150 R and the swings' 1e3 to 1e4 R: a bound on R alone (10 R, 0.12 m/s^2
   rms) found 13 rests for the right foot's 30 stances, 18 % of their
   samples (stride error 12.4 %, against 4.6 % with reference stances); with
   the tremor term 33 rests and 5.2 % (tests/test_real_walk.py; tremor 0.1
   to 0.2 give the same within 0.2 %).
   On pure sensor noise the statistic is chi2(n (W - 1)) / (n (W - 1)) or
   less, whose 0.1 % upper quantile is 2.3 for W = 11 and two axes. For the
   ADXL250 default (R = 0.016) the bound moves from 10 R to 19 R, which the
   simulated walks and stop-and-go runs do not notice (they have no tremor;
   3 to 30 R gave the same results there). The price is on a very quiet
   sensor in a vehicle (the ADXL202 duty-cycle model, R = 6.2e-5, 2300 R):
   the first 2 cm/s of a gentle start now pass the quiet test and only the
   level test trims them (stop-and-go rms 2.0 / 2.3 cm against 2.0 / 1.7 cm);
2. **level**: the length of the vector of window means is at most
   ``level``: the larger of three standard deviations of the bias about its
   model plus three of the window mean (as before), and ``level_min``
   (0.3 m/s^2, the gravity leaking through about 1.75 degrees of tilt
   error). This refuses the constant-acceleration holds of a vehicle
   (1 m/s^2 and more), which pass the quiet test, and most of the gentle
   start of a move;
3. every sample of the window valid (not clipped, finite) on every axis.

Samples whose window passes are rest candidates; runs of them less than
``bridge_s`` (0.1 s, one window) apart are joined, so that a knock or a
glitch inside a rest, which fails every window holding it, does not split
the rest in two (whose second half the gate would then judge on a velocity
integral that carries the knock); each run is widened
by ``widen`` * (W // 2) samples on both sides (default half of the window's
half-width: every sample of a passing window was quiet, but a vehicle's move
starts so gently that the full width puts updates on its first few cm/s) and
kept if it lasts at least ``min_rest_s``. An impact spike fails the quiet test in
every window that holds it, so it can end a rest but never lengthen one.

The gate (once per rest, for every axis at once)
-------------------------------------------------
Quiet and level cannot tell a rest from coasting at constant velocity. Each
candidate rest is therefore tested once, on the velocity v_j that its start
would have if the body had been at rest at the end of the previous accepted
rest: v_j = Ts sum (z_j - b_j) over the samples in between, where b_j is the
mean reading of axis j over that previous rest, leaving out samples more
than 5 sqrt(R_j) from the rest's median (a knock) (the model's bias mean before
the first rest). Re-measuring the bias at every rest absorbs a slowly changing
tilt leak, and nothing here depends on the Kalman filter's own velocity, so a
filter that drifted during a swing never makes a rest be refused. The rest
is accepted when either

* mean_j v_j^2 / s_j^2 <= ``gate`` (default 16), with
  s_j^2 = (sd(b_j) D)^2 + R_j Ts^2 m + sigma^2 over a span of m samples,
  D = m Ts, sd(b_j) = sqrt(R_j / samples kept) (the model's bias spread
  before the first rest), or
* |v| <= ``rel`` |v|_max (default 0.5): the speed has come back to half of
  the largest speed reached since the previous rest. A coast, a cruise keep
  their peak speed; a foot that landed has come back from it, even when a
  heel strike sampled on three or four points left a velocity error of a
  good fraction of a metre per second in the integral.

``gate = 0`` accepts every candidate.

Measurements: every sample of an accepted rest gets a zero-velocity update
(:func:`accelnav.estimate.kf.zero_velocity`, u = 0 with standard deviation
``sigma``), applied to every axis (``every_s`` > 0 thins them to one per
every_s seconds). Dense updates matter on short stances: one per 0.1 s gives
a 0.35 s stance three or four.

All thresholds have command-line overrides (``accelnav smooth --zupt-*``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from accelnav.estimate.kf import Aids, Measurement, bias_model
from accelnav.fileio import check_input, excerpt, load_npz
from accelnav.model.design import axis_design
from accelnav.model.load import Model


@dataclass(frozen=True)
class ZuptParams:
    window_s: float = 0.1  # s, centred window of the moving mean and variance
    var_k: float = 10.0  # quiet if mean over axes of window variance / (R + tremor^2) <= var_k
    tremor: float = 0.12  # m/s^2 rms, the motion of a body at rest (a stance's sway, an idling engine)
    level: float | None = None  # m/s^2, bound on |window means - bias means|; None: from the model
    level_min: float = 0.3  # m/s^2, the model-derived level is raised to at least this
    min_rest_s: float = 0.1  # s, shortest rest kept (after widening)
    bridge_s: float = 0.1  # s, a break in a rest this short (a knock, a glitch) does not split it
    widen: float = 0.5  # runs of window centres are widened by widen * (W // 2) samples on both sides
    sigma: float = 0.02  # m/s, standard deviation of each zero-velocity update
    every_s: float = 0.0  # s, one update per every_s within a rest; 0: every sample
    gate: float = 16.0  # per-rest chi-square bound (mean over axes); 0 accepts every candidate rest
    rel: float = 0.5  # per-rest: also accepted if |v| <= rel * the largest |v| since the previous rest


def window_samples(model: Model, p: ZuptParams) -> int:
    w = max(3, int(round(p.window_s * model.rate_hz)))
    return w if w % 2 else w + 1


def resolved(model: Model, p: ZuptParams) -> ZuptParams:
    """``p`` with the level threshold filled in from the model (see the module docstring)."""
    for name in ("window_s", "var_k", "sigma"):
        v = getattr(p, name)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"zupt {name}: got {v}; accepted: a number > 0")
    for name in ("every_s", "min_rest_s", "level_min", "rel", "widen", "bridge_s", "tremor"):
        v = getattr(p, name)
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"zupt {name}: got {v}; accepted: a number >= 0")
    if not (math.isfinite(p.gate) and p.gate >= 0):
        raise ValueError(f"zupt gate: got {p.gate}; accepted: a number >= 0 (0: no gate)")
    if p.level is not None:
        if not (math.isfinite(p.level) and p.level > 0):
            raise ValueError(f"zupt level: got {p.level}; accepted: a number > 0 (m/s^2)")
        return p
    return replace(p, level=max(model_level(model, p), p.level_min))


def model_level(model: Model, p: ZuptParams) -> float:
    """Three standard deviations of the bias about its model plus three of a window mean, m/s^2."""
    w = window_samples(model, p)
    T = max(ax.T for ax in model.axes)
    s0 = model.filter.initial_sigma[3]
    spread = math.sqrt(s0**2 + model.noise.sigma_eps**2 * T / 2.0)
    return 3.0 * spread + 3.0 * math.sqrt(model.noise.R / w)


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


def candidates(accel: np.ndarray, clipped: np.ndarray, model: Model, params: ZuptParams = ZuptParams()) -> np.ndarray:
    """(N,) bool: samples the detector calls rest, before the per-rest gate (see the module docstring).

    ``accel``, ``clipped`` are (N, n_axes) as in a run file; columns are the model's axes in order.
    """
    p = resolved(model, params)
    x, ok, R = _prepared(accel, clipped, model)
    n, n_axes = x.shape
    w = window_samples(model, p)
    bad = _moving((~ok.all(axis=1)).astype(np.float64), w)
    quiet = np.zeros(n)
    mean2 = np.zeros(n)
    for j in range(n_axes):
        s1 = _moving(x[:, j], w)
        s2 = _moving(x[:, j] * x[:, j], w)
        with np.errstate(invalid="ignore"):
            mean = s1 / w
            quiet += (s2 - w * mean * mean) / (w - 1) / (R[j] + p.tremor**2)
            mean2 += mean * mean
    with np.errstate(invalid="ignore"):
        centre = (bad == 0) & (quiet / n_axes <= p.var_k) & (mean2 <= p.level**2)
    # widen each run of passing window centres to the windows' extent, drop the short ones
    h = int(round(p.widen * (w // 2)))
    runs = [(max(0, a - h), min(n, b + h)) for a, b in intervals(centre)]
    # bridge short breaks: one spike fails every window that holds it, W samples of centres
    bridge = int(round(p.bridge_s * model.rate_hz))
    merged: list[list[int]] = []
    for a, b in runs:
        if merged and a - merged[-1][1] <= bridge:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    rest = np.zeros(n, dtype=bool)
    shortest = max(1, int(round(p.min_rest_s * model.rate_hz)))
    for a, b in merged:
        if b - a >= shortest:
            rest[a:b] = True
    return rest


@dataclass(frozen=True)
class RestDecision:
    """The gate's verdict on one candidate rest [start, stop)."""

    start: int
    stop: int
    accepted: bool
    chi2: float  # mean over axes of v_j^2 / s_j^2
    speed: float  # |v| at the rest's start, m/s
    peak: float  # largest |v| since the previous accepted rest, m/s


def gate_rests(
    accel: np.ndarray, clipped: np.ndarray, rest: np.ndarray, model: Model, params: ZuptParams = ZuptParams()
) -> list[RestDecision]:
    """Decide once per candidate rest, for all axes together (see the module docstring)."""
    p = resolved(model, params)
    x, ok, R = _prepared(accel, clipped, model)
    n, n_axes = x.shape
    Ts = model.Ts
    b = np.zeros(n_axes)  # bias correction on top of the model's bias mean
    sd_b = np.full(n_axes, model.filter.initial_sigma[3])
    u0 = model.filter.initial_sigma[1]
    since = 0
    out = []
    for a, stop in intervals(rest):
        seg = x[since:a] - b
        seg[~ok[since:a]] = 0.0
        m = a - since
        v_path = np.cumsum(seg, axis=0) * Ts
        v = v_path[-1] if m else np.zeros(n_axes)
        peak = float(np.sqrt((v_path**2).sum(axis=1)).max()) if m else 0.0
        s2 = (sd_b * m * Ts) ** 2 + R * Ts * Ts * m + p.sigma**2 + u0**2
        chi2 = float(np.mean(v * v / s2))
        speed = float(np.sqrt(v @ v))
        accepted = p.gate == 0 or chi2 <= p.gate or speed <= p.rel * peak
        out.append(RestDecision(a, stop, bool(accepted), chi2, speed, peak))
        if accepted:
            use = ok[a:stop].all(axis=1)
            if use.any():
                b, kept = _robust_mean(x[a:stop][use], R)
                sd_b = np.sqrt(R / kept)
            since, u0 = stop, 0.0
    return out


def _robust_mean(x: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column, the mean of the samples within 5 sqrt(R) of the median (a knock left out), and their count.

    Not the median itself: a coarse ADC (the default's step is 3.6 sqrt(R)) puts the median on a code.
    """
    med = np.median(x, axis=0)
    near = np.abs(x - med) <= 5.0 * np.sqrt(R)
    kept = np.maximum(near.sum(axis=0), 1)
    return np.where(near, x, 0.0).sum(axis=0) / kept, kept


def rest_mask(accel: np.ndarray, clipped: np.ndarray, model: Model, params: ZuptParams = ZuptParams()) -> np.ndarray:
    """(N,) bool: samples of the accepted rests (detector, then the per-rest gate)."""
    rest = candidates(accel, clipped, model, params)
    mask = np.zeros(len(rest), dtype=bool)
    for r in gate_rests(accel, clipped, rest, model, params):
        if r.accepted:
            mask[r.start : r.stop] = True
    return mask


def intervals(mask: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in ``mask`` as (first, last + 1) sample pairs."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def update_samples(mask: np.ndarray, model: Model, params: ZuptParams = ZuptParams()) -> np.ndarray:
    """Sample indices that get a zero-velocity update: every sample of each rest run, or every every_s seconds
    (counted from the run's first sample). Whole-array operations: no Python loop over the rests."""
    step = max(1, int(round(params.every_s * model.rate_hz)))
    m = np.asarray(mask, dtype=bool).reshape(-1)
    idx = np.flatnonzero(m).astype(np.int64)
    if step == 1 or not len(idx):
        return idx
    starts = m.copy()
    starts[1:] &= ~m[:-1]
    run_start = np.maximum.accumulate(np.where(starts, np.arange(len(m)), 0))[idx]
    return idx[(idx - run_start) % step == 0]


def measurements(ks: np.ndarray, params: ZuptParams = ZuptParams()) -> tuple[list[Measurement], list[float]]:
    """Zero-velocity updates at samples ``ks`` and their gates (for accelnav.estimate.fastsmooth.smooth)."""
    extras = Aids.zero_velocity(ks, params.sigma).measurements()
    return extras, [params.gate] * len(extras)


def axis_aids(rest: np.ndarray, sigma: np.ndarray | None, model: Model, params: ZuptParams = ZuptParams()) -> Aids:
    """The zero-velocity updates of one axis as arrays: at the samples of its (N,) rest mask that get one
    (:func:`update_samples`), with the per-sample ``sigma`` of a ZUPT file where it gives one (NaN or None:
    ``params.sigma``)."""
    ks = update_samples(rest, model, params)
    sd = np.full(len(ks), float(params.sigma))
    if sigma is not None:
        given = np.asarray(sigma, dtype=np.float64)[ks]
        sd = np.where(np.isfinite(given), given, sd)
    return Aids.zero_velocity(ks, sd)


def axis_updates(
    rest: np.ndarray, sigma: np.ndarray | None, model: Model, params: ZuptParams = ZuptParams()
) -> tuple[np.ndarray, list[Measurement]]:
    """:func:`axis_aids` as (samples, one :class:`Measurement` each), for callers that mix them with fixes."""
    a = axis_aids(rest, sigma, model, params)
    return a.k, a.measurements()


def intervals_from_csv(path, t: np.ndarray) -> np.ndarray:
    """A rest mask from a CSV of intervals (columns start_s, end_s; inclusive), on the sample times t."""
    mask, _ = read_zupt_file(path, t, ["_"])
    return mask[:, 0]


def read_zupt_file(path, t: np.ndarray, axis_names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Zero-velocity updates given by the user: ((N, n_axes) bool mask, (N, n_axes) sigma [m/s], NaN = default).

    Two forms, told apart by content:

    * **intervals**, CSV with columns ``start_s,end_s`` (inclusive, on the run's
      clock), and optionally ``axis`` (an axis name of the run; without it
      the interval holds for every axis) and ``sigma`` (m/s, the updates'
      standard deviation there; default ``--zupt-sigma``);
    * **per-sample mask**: an NPZ with a 0/1 array ``rest`` of N samples (or
      (N, n_axes)), or a CSV with a header ``rest`` (optionally ``t_s,rest``)
      and one 0/1 row per sample of the run.
    """
    from accelnav.errors import UserError
    from accelnav.estimate.fixes import read_table

    t = np.asarray(t, dtype=np.float64)
    n, n_axes = len(t), len(axis_names)
    path_s = str(path)
    sig = np.full((n, n_axes), np.nan)
    check_input(path)  # a FIFO or a device is refused before it is read
    try:
        with open(path, "rb") as fh:
            head = fh.read(2)
    except OSError as exc:
        raise UserError(f"{path_s}: cannot read: {exc.strerror}") from None
    if head == b"PK":
        f = load_npz(path)  # sizes checked before anything is inflated
        if "rest" not in f:
            raise UserError(f"{path_s}: no 'rest' array; keys: {excerpt(', '.join(f)) if f else 'none'}")
        return _mask_from(np.asarray(f["rest"]), n, n_axes, path_s), sig
    with open(path, encoding="utf-8", errors="replace") as fh:
        first = fh.readline().strip().replace(" ", "")
    if first in ("rest", "t_s,rest", "t,rest"):
        rows = read_table(path, required=("rest",), optional=("t_s", "t"))
        return _mask_from(np.asarray(rows["rest"]), n, n_axes, path_s), sig
    rows = read_table(path, required=("start_s", "end_s"), optional=("axis", "sigma"))
    mask = np.zeros((n, n_axes), dtype=bool)
    for i, (a, b) in enumerate(zip(rows["start_s"], rows["end_s"], strict=True)):
        if not b >= a:
            raise UserError(f"{path_s}: row {i + 2}: end_s {b:g} is before start_s {a:g}")
        cols = list(range(n_axes))
        if "axis" in rows:
            ax = rows["axis"][i]
            if ax not in axis_names:
                raise UserError(f"{path_s}: row {i + 2}: axis {ax!r}; accepted: {', '.join(axis_names)}")
            cols = [axis_names.index(ax)]
        within = (t >= a) & (t <= b)
        for j in cols:
            mask[within, j] = True
            if "sigma" in rows:
                sd = rows["sigma"][i]
                if not sd > 0:
                    raise UserError(f"{path_s}: row {i + 2}: sigma is {sd:g}; accepted: a standard deviation > 0 (m/s)")
                sig[within, j] = sd
    return mask, sig


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
