"""Rests seen by the accelerometer and the gyroscope together: a SHOE-style detector.

Skog et al. (2010, "Zero-velocity detection: an algorithm evaluation") compare detectors for foot-mounted
IMUs; the best, SHOE, is the generalised likelihood ratio of "the body is still" over a window of W
samples, which reduces to two sums: how far each specific force is from one constant gravity vector of
magnitude g, and how large the angular rate is. Here the two are read in physical units:

    T = mean_W |a_k - g a_bar/|a_bar||^2 / acc_tol^2  +  mean_W |w_k - b|^2 / gyro_tol^2  <=  1

``acc_tol`` (m/s^2) is the rms departure of the specific force from a still gravity vector a rest may
show, ``gyro_tol`` (rad/s) the rms angular rate it may show (b: the gyroscope's bias, when known), the
two added in quadrature (SHOE's threshold gamma is 1 on this scale). The defaults (0.4 m/s^2, 0.5 rad/s)
were measured on real recordings: on gaitmap's foot walk a mid-stance turns at 0.3-0.65 rad/s (the window's
rms) as the foot rolls over and its specific force stays within 0.25-0.45 m/s^2 of gravity, the swing turns
at 3-10 rad/s; every reference stance of both feet holds a rest, 97 % of the motion-capture mid-stances
are inside one. On mobgap's lower-back walks (quiet standing 0.02-0.05 rad/s, walking 0.2-0.9 rad/s with
1-3 m/s^2) 0-5 % of the walking is called rest; with the looser (1.0 m/s^2, 0.6 rad/s) 14-19 % was. The
accelerometer term alone cannot tell a smooth cruise from a
stop (accelnav.estimate.zupt's candidates, the path for parts without a gyroscope); the gyroscope term
sees the turning a moving foot or body cannot avoid.

The window is centred; a centre that passes makes every sample of its window a rest sample (every sample
in it was seen still), and runs shorter than ``min_rest_s`` are dropped. All of it is vectorised:
moving sums by cumulative sums, no loop over samples.

A foot's tolerance is not stillness: a slowly hand-moved unit (1 m/s^2, 0.25 rad/s) stays inside it
throughout and was called 99 % rest. :func:`find_rests` therefore decides on all the evidence:

* **the sensor's own noise** (rms per axis), measured over the record's quietest windows of
  ``NOISE_WINDOW_S`` (or stated: ``acc_noise``, ``gyro_noise``), proven only where those windows vary,
  turn and accelerate as little as a still sensor can (else the note says why and the tolerances decide
  alone). A window is *still* where its angular rate (less the quiet windows' bias) and its specific
  force's departure from their g are both within ``noise_k`` times that noise;
* the SHOE tolerance test above gives *candidates* (a foot's rolling stance);
* every run of still or candidate samples is a hypothesis: its specific force, held in a frame the
  gyroscope fixes, less its mean (gravity, wherever it points), integrated, is the speed it implies; a
  rest implies at most ``speed_tol`` (gravity turns in the body only as the gyroscope says). A run that
  implies more keeps only its still parts that pass the same test;
* a candidate holding no still sample is also compared with gravity as the still rests show it,
  carried by the gyroscope (within ``GRAVITY_REACH_S`` and ``GRAVITY_REACH_RAD`` of turning): off by
  more than ``acc_tol``, it is a move (a short quiet spell inside a smooth move passes every window test).

The notes say which evidence refused what; ``still`` marks the rests that prove stillness (the only ones
a gyroscope's bias may be measured over).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from accelnav.errors import UserError
from accelnav.level.quat import integrate, rotate

G = 9.80665  # m/s^2, the standard gravity (the level frame subtracts it)


@dataclass(frozen=True)
class RestParams:
    window_s: float = 0.05  # s, centred window of the test (SHOE's W: 3-11 samples at 100-200 Hz)
    acc_tol: float = 0.4  # m/s^2, rms departure of the specific force from one still gravity vector
    gyro_tol: float = 0.5  # rad/s (29 deg/s), rms angular rate a rest may show (a foot rolling in stance)
    min_rest_s: float = 0.05  # s, shorter runs of still samples are dropped
    speed_tol: float = 0.1  # m/s, the speed a rest's specific force may imply (gravity turning unexplained)
    noise_k: float = 3.0  # a still window's rms within this many times the sensor's noise (per axis)
    acc_noise: float | None = None  # m/s^2 rms per axis, the sensor's stated noise; None: measured
    gyro_noise: float | None = None  # rad/s rms per axis, the sensor's stated noise; None: measured

    def checked(self) -> RestParams:
        for name in ("window_s", "acc_tol", "gyro_tol", "speed_tol", "noise_k"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise UserError(f"rest detector {name}: got {v}; accepted: a number > 0")
        for name in ("acc_noise", "gyro_noise"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise UserError(f"rest detector {name}: got {v}; accepted: a number > 0, or None (measured)")
        if (self.acc_noise is None) != (self.gyro_noise is None):
            raise UserError("rest detector: state both acc_noise and gyro_noise, or neither (both measured)")
        if not (math.isfinite(self.min_rest_s) and self.min_rest_s >= 0):
            raise UserError(f"rest detector min_rest_s: got {self.min_rest_s}; accepted: a number >= 0")
        return self


def _window(rate: float, window_s: float) -> int:
    w = max(3, int(round(window_s * rate)))
    return w if w % 2 else w + 1


def _centred_mean(x: np.ndarray, w: int) -> np.ndarray:
    """Mean over the centred window of ``w`` (odd) samples of each row of ``x`` (N, ...), edges padded."""
    h = w // 2
    pad = np.concatenate([np.repeat(x[:1], h, axis=0), x, np.repeat(x[-1:], h, axis=0)])
    c = np.cumsum(pad, axis=0)
    c = np.concatenate([np.zeros_like(c[:1]), c])
    return (c[w:] - c[:-w]) / w


def shoe_statistic(
    acc: np.ndarray, gyro: np.ndarray, rate: float, params: RestParams = RestParams(), bias: np.ndarray | None = None
) -> np.ndarray:
    """(N,) the test statistic T of the module docstring at each window centre (rest where T <= 1)."""
    p = params.checked()
    dev, mean_w2 = _terms(acc, gyro, _window(rate, p.window_s), bias, G)
    return dev / p.acc_tol**2 + mean_w2 / p.gyro_tol**2


def _terms(acc: np.ndarray, gyro: np.ndarray, w: int, bias: np.ndarray | None, g: float):
    """Per window centre: mean |a - g a_bar/|a_bar||^2 (m^2/s^4) and mean |w - b|^2 (rad^2/s^2)."""
    wb = gyro if bias is None else gyro - bias
    mean_a = _centred_mean(acc, w)
    mean_a2 = _centred_mean(np.einsum("ij,ij->i", acc, acc), w)
    mean_w2 = _centred_mean(np.einsum("ij,ij->i", wb, wb), w)
    # mean |a - g u|^2 with u = a_bar/|a_bar|: mean |a|^2 - 2 g |a_bar| + g^2
    dev = np.maximum(mean_a2 - 2.0 * g * np.linalg.norm(mean_a, axis=1) + g * g, 0.0)
    return dev, mean_w2


def still_mask(
    acc: np.ndarray, gyro: np.ndarray, rate: float, params: RestParams = RestParams(), bias: np.ndarray | None = None
) -> np.ndarray:
    """(N,) bool: the samples of the rests (every sample of a window whose centre passes; short runs dropped)."""
    p = params.checked()
    return _dilated(shoe_statistic(acc, gyro, rate, p, bias) <= 1.0, rate, p)


def _dilated(centre: np.ndarray, rate: float, p: RestParams) -> np.ndarray:
    """Every sample within w // 2 of a passing centre (a dilation by a moving sum), short runs dropped."""
    w = _window(rate, p.window_s)
    mask = _centred_mean(centre.astype(np.float64), w) > 0.5 / w
    return drop_short(mask, int(math.ceil(p.min_rest_s * rate)))


def spans(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs of True in ``mask`` as half-open (start, stop) sample spans."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def drop_short(mask: np.ndarray, n: int) -> np.ndarray:
    """``mask`` without its runs shorter than ``n`` samples."""
    out = np.zeros(len(mask), dtype=bool)
    for a, b in spans(mask):
        if b - a >= n:
            out[a:b] = True
    return out


# --- the recording's own noise, and the decision on all the evidence ---------------------------------------

NOISE_WINDOW_S = 0.25  # s, the windows the noise is read in
QUIET_SHARE = 0.05  # the quietest share of those windows gives the noise (at least QUIET_MIN of them)
QUIET_MIN = 2
ACC_NOISE_FLOOR = 0.002  # m/s^2: no accelerometer reads quieter (a noise-free simulation gets this)
GYRO_NOISE_FLOOR = 2e-4  # rad/s (0.01 deg/s): no gyroscope reads quieter
ACC_NOISE_MAX = 0.1  # m/s^2 rms: quieter windows than this prove nothing beyond a foot's tolerance
GYRO_NOISE_MAX = 0.02  # rad/s rms (1.1 deg/s): the same for the gyroscope
BIAS_MAX = 0.1  # rad/s (5.7 deg/s): a quiet window turning faster than this is a turn, not a bias
G_OFF_MAX = 0.5  # m/s^2: quiet windows whose specific force is further from g are not still
COVER_MAX = 0.6  # rests covering more of a record than this are said to be suspect (a record mostly moves)
GRAVITY_REACH_S = 10.0  # s, the gyroscope carries gravity's direction from a still rest this long
GRAVITY_REACH_RAD = 2.0  # rad turned: a 1 % scale error tilts by 0.02 rad (0.2 m/s^2) over this much turning


@dataclass(frozen=True)
class Noise:
    """The sensor's noise (rms per axis) and what the quietest windows read: ``acc`` m/s^2, ``gyro`` rad/s,
    ``g`` the magnitude of their specific force, ``bias`` their mean rate (rad/s); ``said`` where from."""

    acc: float
    gyro: float
    g: float
    bias: np.ndarray
    said: str


@dataclass(frozen=True)
class RestFinding:
    """What the detector decided: ``mask`` (N,) the rests; ``still`` (N,) the part of them still within the
    sensor's noise (the rests that prove stillness: a gyroscope's bias is measurable there); ``noise`` the
    noise they were judged against (None: the record proves none); ``notes`` which evidence decided."""

    mask: np.ndarray
    still: np.ndarray
    noise: Noise | None
    notes: tuple[str, ...]


def measure_noise(acc: np.ndarray, gyro: np.ndarray, rate: float) -> tuple[Noise | None, str]:
    """The noise of the quietest windows of ``NOISE_WINDOW_S``, or None and why when they prove no rest
    (too few windows, or the quietest still vary, turn or accelerate beyond what a still sensor shows)."""
    w = max(5, int(round(NOISE_WINDOW_S * rate)))
    m = acc.shape[0] // w
    if m < QUIET_MIN:
        return None, f"the record is shorter than {QUIET_MIN} windows of {NOISE_WINDOW_S:g} s"
    a = acc[: m * w].reshape(m, w, 3)
    g = gyro[: m * w].reshape(m, w, 3)
    va = a.var(axis=1).mean(axis=1)  # per-axis variance about the window's mean
    vg = g.var(axis=1).mean(axis=1)
    k = max(QUIET_MIN, int(math.ceil(QUIET_SHARE * m)))
    quiet = np.argsort(va / ACC_NOISE_MAX**2 + vg / GYRO_NOISE_MAX**2, kind="stable")[:k]
    sa, sg = float(np.sqrt(np.median(va[quiet]))), float(np.sqrt(np.median(vg[quiet])))
    rates = g[quiet].mean(axis=1)
    gmag = float(np.median(np.linalg.norm(a[quiet].mean(axis=1), axis=1)))
    turn = float(np.degrees(np.linalg.norm(rates, axis=1).max()))
    where = f"its quietest {k * w / rate:.3g} s ({k} windows of {NOISE_WINDOW_S:g} s)"
    if sa > ACC_NOISE_MAX or sg > GYRO_NOISE_MAX:
        why = f"{where} vary by {sa:.3g} m/s^2 and {sg:.3g} rad/s rms (a still sensor: <= {ACC_NOISE_MAX:g}, "
        return None, why + f"{GYRO_NOISE_MAX:g})"
    if turn > math.degrees(BIAS_MAX):
        return None, f"{where} turn at up to {turn:.3g} deg/s (more than a bias, {math.degrees(BIAS_MAX):.3g})"
    if abs(gmag - G) > G_OFF_MAX:
        return None, f"{where} read a specific force of {gmag:.4g} m/s^2, not g"
    raised = ", raised to the floor no sensor reads below" if sa < ACC_NOISE_FLOOR or sg < GYRO_NOISE_FLOOR else ""
    floor = (max(sa, ACC_NOISE_FLOOR), max(sg, GYRO_NOISE_FLOOR))
    return Noise(*floor, gmag, rates.mean(axis=0), f"measured over {where}{raised}"), ""


def implied_speed(c: np.ndarray, runs: list[tuple[int, int]]) -> np.ndarray:
    """Per run, the largest speed its specific force implies when the run is a rest: the specific force in a
    frame fixed by the gyroscope, less its mean over the run (gravity, wherever it points), integrated;
    at a rest gravity's direction in the body turns only as the gyroscope says and this stays near zero.
    ``c`` (N + 1, 3): that specific force's running integral from the start (m/s), computed once."""
    out = np.zeros(len(runs))
    for i, (a, b) in enumerate(runs):
        v = c[a : b + 1] - c[a]
        v -= np.linspace(0.0, 1.0, b - a + 1)[:, None] * v[-1]  # the run's mean force removed
        out[i] = float(np.sqrt(np.einsum("ij,ij->i", v, v).max()))
    return out


def find_rests(t: np.ndarray, acc: np.ndarray, gyro: np.ndarray, params: RestParams = RestParams()) -> RestFinding:
    """The rests of a gyroscope-equipped recording, decided on all the evidence (module docstring)."""
    p = params.checked()
    rate = (t.size - 1) / float(t[-1] - t[0])
    notes = []
    noise, why = measure_noise(acc, gyro, rate)
    if p.acc_noise is not None:  # the stated figures; the quietest windows' bias and g where they prove them
        g, b = (G, np.zeros(3)) if noise is None else (noise.g, noise.bias)
        noise, why = Noise(p.acc_noise, p.gyro_noise, g, b, "as stated"), ""
    cand = still_mask(acc, gyro, rate, p)
    if noise is None:
        still = np.zeros(t.size, dtype=bool)
        notes.append(f"the record proves no noise floor: {why}; stillness judged by the tolerances alone")
        bias = np.zeros(3)
    else:
        dev, w2 = _terms(acc, gyro, _window(rate, p.window_s), noise.bias, noise.g)
        k2 = 3.0 * p.noise_k**2  # three axes
        still = _dilated((dev <= k2 * noise.acc**2) & (w2 <= k2 * noise.gyro**2), rate, p)
        notes.append(
            f"sensor noise {noise.acc:.2g} m/s^2, {noise.gyro:.2g} rad/s rms per axis ({noise.said}); "
            f"still: within {p.noise_k:g}x of it"
        )
        bias = noise.bias
    f_world = rotate(integrate(t, gyro - bias), acc)
    c = np.concatenate([np.zeros((1, 3)), np.cumsum(f_world, axis=0) / rate])
    runs = spans(cand | still)
    speed = implied_speed(c, runs)
    turned = np.cumsum(np.linalg.norm(gyro - bias, axis=1)) / rate
    gravity = _gravity_carried(f_world, t, turned, still, runs)
    mask = np.zeros(t.size, dtype=bool)
    refused, tilted = [], []
    for (a, b), v, off in zip(runs, speed, gravity, strict=True):
        if v <= p.speed_tol and not off > p.acc_tol:
            mask[a:b] = True
            continue
        (refused if v > p.speed_tol else tilted).append((a, b, v if v > p.speed_tol else off))
        parts = [(a + lo, a + hi) for lo, hi in spans(still[a:b])]
        for (lo, hi), u in zip(parts, implied_speed(c, parts), strict=True):
            if u <= p.speed_tol:
                mask[lo:hi] = True
    why_refused = (
        (
            refused,
            "gravity turns in the body beyond what the gyroscope explains (up to {:.3g} m/s implied, a rest "
            f"<= {p.speed_tol:g}); their still parts kept",
        ),
        (
            tilted,
            "their specific force is up to {:.3g} m/s^2 from the gravity the gyroscope carries from the "
            f"still rests (a rest <= {p.acc_tol:g})",
        ),
    )
    for runs_out, said in why_refused:
        if runs_out:
            secs = sum(b - a for a, b, _ in runs_out) / rate
            top = max(v for _, _, v in runs_out)
            many = "candidate stretches" if len(runs_out) > 1 else "candidate stretch"
            notes.append(f"{len(runs_out)} {many} ({secs:.3g} s) refused: " + said.format(top))
    mask = drop_short(mask, int(math.ceil(p.min_rest_s * rate)))
    if mask.mean() > COVER_MAX:
        notes.append(
            f"rests cover {mask.mean():.0%} of the record (> {COVER_MAX:.0%}): too much to trust them all still"
        )
    return RestFinding(mask, mask & still, noise, tuple(notes))


def _gravity_carried(
    f_world: np.ndarray, t: np.ndarray, turned: np.ndarray, still: np.ndarray, runs: list[tuple[int, int]]
) -> np.ndarray:
    """Per run holding no still sample, how far (m/s^2) its mean specific force lies from gravity as the still
    rests show it in the gyroscope's frame (interpolated in time between them): NaN where no still rest lies
    within ``GRAVITY_REACH_S`` or ``GRAVITY_REACH_RAD`` of turning (``turned``: the angle turned since the
    start, rad; the gyroscope's drift and scale error would decide) and for runs that hold a still sample."""
    out = np.full(len(runs), np.nan)
    anchors = spans(still)
    if not anchors:
        return out
    mids = np.array([0.5 * (t[a] + t[b - 1]) for a, b in anchors])
    mid_turn = np.array([turned[(a + b) // 2] for a, b in anchors])
    g = np.array([f_world[a:b].mean(axis=0) for a, b in anchors])
    for i, (a, b) in enumerate(runs):
        tm = 0.5 * (t[a] + t[b - 1])
        near = (np.abs(mids - tm) <= GRAVITY_REACH_S) & (np.abs(mid_turn - turned[(a + b) // 2]) <= GRAVITY_REACH_RAD)
        if still[a:b].any() or not near.any():
            continue
        ref = np.array([np.interp(tm, mids, g[:, k]) for k in range(3)])
        out[i] = float(np.linalg.norm(f_world[a:b].mean(axis=0) - ref))
    return out
