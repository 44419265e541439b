"""Truth trajectories along one axis: position r, velocity u, acceleration a.

Conventions
-----------
* SI units: t in s, r in m, u in m/s, a in m/s^2; all arrays float64.
* ``t`` is the sample grid, uniform, starting at 0. The truth is a
  continuous-time function evaluated at those instants, so r, u and a are
  exactly consistent (u = dr/dt, a = du/dt) up to float64 rounding.
* Every scenario starts at rest at the origin: r(0) = u(0) = 0, a(0) = 0,
  which is the filter's prior (x0 = [0, 0, 0, c2], sigma_r = sigma_u = 0).
* ``truth`` draws all its random numbers from the generator it is given, in
  fixed-size chunks, so a shorter run is a prefix of a longer run with the
  same generator state.

Building block: the smooth step
-------------------------------
Every scenario except ``stationary`` and ``sinusoid`` is a chain of
segments. In segment j, of duration d and starting at state (r0, u0, a0),
the acceleration moves from a0 to a0 + A along half a raised cosine
(A = 0 is a hold at a0). With s the time into the segment, x = s/d and
sigma(x) = (1 - cos(pi x)) / 2:

    a(s) = a0 + A sigma(x)
    u(s) = u0 + a0 s + A (s/2 - d/(2 pi) sin(pi x))
    r(s) = r0 + u0 s + a0 s^2/2 + A (s^2/4 - d^2/pi^2 sin^2(pi x / 2))

These are exact integrals of one another; a is continuous with a continuous
derivative (the jerk A pi/(2 d) sin(pi x) is zero at both ends), so the
motion is smooth enough for any filter and numerical differentiation at a
fine grid recovers it.

A *move* is eight such segments, always in this order:

    rest | up +A1 (e1) | hold (f1) | down -A1 (e1) | coast (c) | down -A2 (e2) | hold (f2) | up +A2 (e2)

The two pulses have equal areas, A1 (e1 + f1) = A2 (e2 + f2), so the move
ends at rest. The states within a move are accumulated from zero at its
rest, never carried over from earlier moves, so every rest has u = a = 0
exactly (not merely to rounding): rests are true rests. The direction (sign)
of each move is chosen to head back towards the origin, which keeps |r|
below the length of one move for any run length.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

SCENARIOS = ("stationary", "stop_and_go", "sinusoid", "vehicle", "stress", "shock", "walking")
# Scenarios whose truth differs per axis and is not a motion along one line (see tumble_specific_force)
MULTI_AXIS_SCENARIOS = ("tumble", "tumble_any")
# Scenarios made to test rest detection (issue 23), with a truth rest mask and sensor-side disturbances
# (tilt and grade leaks, vibration); see rest_truth and accelnav.hil_sim.sim.walking
WALK_SCENARIOS = ("walking_drift", "walking_fast", "walking_still_start", "jogging")
# Cases where a rest decision must weigh other evidence (issue 31): a cruise that looks still, stops between
# fixes, a hand-moved box, a mount that tilts; with FIX_PLANS, the position fixes a user would have
LINE_SCENARIOS = (
    "stop_and_go_graded",
    "highway",
    "cart_push",
    "highway_gnss",
    "town_drive",
    "hand_box",
    "tilting_mount",
)
REST_SCENARIOS = (*WALK_SCENARIOS, *LINE_SCENARIOS)
ALL_SCENARIOS = SCENARIOS + MULTI_AXIS_SCENARIOS + REST_SCENARIOS
# Scenarios that come with position fixes: (period s, sigma m); see scenario_fixes
FIX_PLANS = {"highway_gnss": (1.0, 1.0), "town_drive": (10.0, 1.0), "hand_box": (5.0, 0.02)}


def require_scenario(name: str, what: str = "scenario", error: type[Exception] = ValueError) -> None:
    """Refuse, in one line naming ``what``, a scenario the simulator does not have (``error``: the caller's
    exception type, e.g. the CLI's UserError with ``what="--scenario"``)."""
    if name not in ALL_SCENARIOS:
        raise error(f"{what}: unknown scenario {name!r}; accepted: {', '.join(repr(s) for s in ALL_SCENARIOS)}")


TUMBLE_HOLD_S = 8.0  # each pose is held this long ...
TUMBLE_TURN_S = 3.0  # ... and the turn to the next one takes this long
TUMBLE_ANY_MIN_TURN_DEG = 45.0  # tumble_any: consecutive random poses differ by at least this much

_CHUNK = 64  # moves drawn per batch of random numbers (fixed: keeps runs prefix-consistent)

# Shock impacts: peak, edge length and flat-top length.
SHOCK_PEAK = 2.5  # times amax; the default ADXL250 rails are at 1.32 amax, an ADXL202's at 2 amax
SHOCK_EDGE_S = 0.010
SHOCK_TOP_S = 0.010  # at least one sample period, so that a sample lands on the flat top
SHOCK_MAX_DV = 30.0  # m/s, cap on the velocity change of one impact (shortens the top if needed)
STRESS_MAX_DV = 20.0  # m/s, velocity change of the largest stress pulse


def truth(name: str, t: np.ndarray, rng: np.random.Generator, amax: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth (r [m], u [m/s], a [m/s^2]) of scenario ``name`` at the instants ``t`` [s].

    ``amax`` is the sensor full scale in m/s^2 (``model.max_accel_m_s2``).
    Scenarios (see :data:`SCENARIOS`):

    * ``stationary``: r = u = a = 0.
    * ``stop_and_go``: rests of 2-8 s alternating with moves: pulses of
      1-3 m/s^2 (edges 0.2-0.8 s, flat top 0-1.5 s), a coast of 0-3 s, then
      the mirror-image braking pulse. Rests have u == 0 and a == 0 exactly.
    * ``sinusoid``: a = A sin(2 pi f t), A in 0.5-2 m/s^2 (at most amax/2),
      f in 0.5-2 Hz; u = A/w (1 - cos wt), r = A/w t - A/w^2 sin wt with
      w = 2 pi f, so r(0) = u(0) = 0. The velocity then has mean A/w > 0 and
      r drifts at that speed (at most 0.64 m/s: 2.3 km in an hour).
    * ``vehicle``: rest 5-20 s, accelerate at 1.5-3 m/s^2 to 5-30 m/s, cruise
      10-60 s, brake at 1-3 m/s^2 to a stop, repeated (out and back).
    * ``stress``: full-scale pulse pairs: peak amax (half the pulses) or
      0.3-1 amax, edges 5-15 ms, flat tops giving a velocity swing of
      5-20 m/s, rests of 0.05-0.3 s between pairs. |a| <= amax exactly.
    * ``shock``: as ``stress``, but a quarter of the pulse pairs are impacts
      of +-2.5 amax (10 ms edges, a flat top of max(10 ms, one sample
      period), velocity swing at most 30 m/s), beyond the sensor's rails.
    * ``walking``: a foot during a walk with turns (:mod:`accelnav.hil_sim.sim.walking`);
      this function returns its first horizontal axis, :func:`simulate
      <accelnav.hil_sim.sim.sensor.simulate>` uses both and the stance mask.
    """
    if name not in SCENARIOS:
        accepted = ", ".join(repr(s) for s in SCENARIOS)
        raise ValueError(f"name: unknown scenario {name!r}; accepted: {accepted}")
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"t: expected a 1-D array of sample times, got shape {t.shape}")
    if not (np.isfinite(amax) and amax > 0):
        raise ValueError(f"amax: expected a positive full scale in m/s^2, got {amax}")
    if t.size == 0 or name == "stationary":
        z = np.zeros_like(t)
        return z, z.copy(), z.copy()
    if name == "sinusoid":
        return _sinusoid(t, rng, amax)
    if name == "walking":
        from .walking import walk

        w = walk(t, rng, amax)
        return w.r[:, 0].copy(), w.u[:, 0].copy(), w.a[:, 0].copy()
    dt = float(t[1] - t[0]) if t.size > 1 else 0.0
    draw = {
        "stop_and_go": _draw_stop_and_go,
        "vehicle": _draw_vehicle,
        "stress": _draw_stress,
        "shock": _draw_shock,
    }[name]
    moves = _draw_moves(lambda: draw(rng, amax, dt), float(t[-1]))
    return _evaluate(moves, t)


# --------------------------------------------------------------------------
# Scenario parameters. Each draw function returns one chunk of _CHUNK moves
# as a dict of (_CHUNK,) arrays: rest, A1, e1, f1, c, A2, e2, f2 (all >= 0;
# A1, A2 are magnitudes) and pref (+-1, the direction used when r == 0).


def _draw_stop_and_go(rng: np.random.Generator, amax: float, dt: float) -> dict[str, np.ndarray]:
    n = _CHUNK
    rest = rng.uniform(2.0, 8.0, n)
    A = np.minimum(rng.uniform(1.0, 3.0, n), 0.5 * amax)
    e = rng.uniform(0.2, 0.8, n)
    f = rng.uniform(0.0, 1.5, n)
    c = rng.uniform(0.0, 3.0, n)
    pref = rng.choice([-1.0, 1.0], n)
    return dict(rest=rest, A1=A, e1=e, f1=f, c=c, A2=A, e2=e, f2=f, pref=pref)


def _pulse_for(dv: np.ndarray, A: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edge and flat-top lengths of a pulse of peak A whose area is dv (shorter edges if dv/A < e)."""
    e = np.minimum(e, dv / A)
    return e, dv / A - e


def _draw_vehicle(rng: np.random.Generator, amax: float, dt: float) -> dict[str, np.ndarray]:
    n = _CHUNK
    rest = rng.uniform(5.0, 20.0, n)
    v = rng.uniform(5.0, 30.0, n)
    A1 = np.minimum(rng.uniform(1.5, 3.0, n), 0.5 * amax)
    e1, f1 = _pulse_for(v, A1, rng.uniform(0.5, 1.5, n))
    c = rng.uniform(10.0, 60.0, n)
    A2 = np.minimum(rng.uniform(1.0, 3.0, n), 0.5 * amax)
    e2, f2 = _pulse_for(v, A2, rng.uniform(0.5, 1.5, n))
    pref = rng.choice([-1.0, 1.0], n)
    return dict(rest=rest, A1=A1, e1=e1, f1=f1, c=c, A2=A2, e2=e2, f2=f2, pref=pref)


def _draw_stress(rng: np.random.Generator, amax: float, dt: float) -> dict[str, np.ndarray]:
    n = _CHUNK
    rest = rng.uniform(0.05, 0.3, n)
    full = rng.random(n) < 0.5
    P = np.where(full, amax, amax * rng.uniform(0.3, 1.0, n))
    e, h = _pulse_for(rng.uniform(5.0, STRESS_MAX_DV, n), P, rng.uniform(0.005, 0.015, n))
    c = rng.uniform(0.0, 0.05, n)
    pref = rng.choice([-1.0, 1.0], n)
    return dict(rest=rest, A1=P, e1=e, f1=h, c=c, A2=P, e2=e, f2=h, pref=pref)


def _draw_shock(rng: np.random.Generator, amax: float, dt: float) -> dict[str, np.ndarray]:
    base = _draw_stress(rng, amax, dt)
    impact = rng.random(_CHUNK) < 0.25
    P = SHOCK_PEAK * amax
    e = min(SHOCK_EDGE_S, SHOCK_MAX_DV / P)
    h = min(max(SHOCK_TOP_S, dt), SHOCK_MAX_DV / P - e)
    for key, value in (("A1", P), ("A2", P), ("e1", e), ("e2", e), ("f1", h), ("f2", h), ("c", 0.0)):
        base[key] = np.where(impact, value, base[key])
    return base


def _sinusoid(t: np.ndarray, rng: np.random.Generator, amax: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    A = min(rng.uniform(0.5, 2.0), 0.5 * amax)
    w = 2.0 * np.pi * rng.uniform(0.5, 2.0)
    wt = w * t
    a = A * np.sin(wt)
    u = A / w * (1.0 - np.cos(wt))
    r = A / w * t - A / w**2 * np.sin(wt)
    return r, u, a


# --------------------------------------------------------------------------
# Moves -> segments -> samples.

_KEYS = ("rest", "A1", "e1", "f1", "c", "A2", "e2", "f2", "pref")


def _draw_moves(draw_chunk: Callable[[], dict[str, np.ndarray]], t_end: float) -> dict[str, np.ndarray]:
    """Draw chunks of moves until they cover [0, t_end]; concatenated parameters."""
    chunks: list[dict[str, np.ndarray]] = []
    covered = 0.0
    while covered <= t_end + 1.0:  # a margin, so rounding in the segment start times cannot matter
        chunk = draw_chunk()
        covered += float(np.sum(_durations(chunk)))
        chunks.append(chunk)
    return {k: np.concatenate([c[k] for c in chunks]) for k in _KEYS}


def _durations(m: dict[str, np.ndarray]) -> np.ndarray:
    """(n_moves, 8) segment durations of the move template."""
    return np.stack([m["rest"], m["e1"], m["f1"], m["e1"], m["c"], m["e2"], m["f2"], m["e2"]], axis=1)


def _steps(m: dict[str, np.ndarray]) -> np.ndarray:
    """(n_moves, 8) acceleration change across each segment, for a move in the + direction."""
    z = np.zeros_like(m["A1"])
    return np.stack([z, m["A1"], z, -m["A1"], z, -m["A2"], z, m["A2"]], axis=1)


def _segment_states(d: np.ndarray, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Start states (r0, u0, a0) of every segment of each move, relative to the move's start at rest.

    Rows are moves, columns the 8 segments. Also returns each move's displacement.
    Each row is accumulated on its own (exclusive cumulative sums along the row).
    """

    def exclusive_cumsum(x: np.ndarray) -> np.ndarray:
        out = np.zeros_like(x)
        np.cumsum(x[:, :-1], axis=1, out=out[:, 1:])
        return out

    a0 = exclusive_cumsum(A)
    u0 = exclusive_cumsum(a0 * d + A * d / 2.0)
    dr = u0 * d + a0 * d**2 / 2.0 + A * d**2 * (0.25 - 1.0 / np.pi**2)
    r0 = exclusive_cumsum(dr)
    return r0, u0, a0, r0[:, -1] + dr[:, -1]


def _evaluate(m: dict[str, np.ndarray], t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = _durations(m)
    A = _steps(m)
    r0, u0, a0, disp = _segment_states(d, A)

    # Direction of each move: back towards the origin (a recursion over moves, not samples).
    sign = np.empty(len(disp))
    r_start = np.empty(len(disp))
    r = 0.0
    for k, (dk, pk) in enumerate(zip(disp, m["pref"], strict=True)):
        s = -1.0 if r > 0 else 1.0 if r < 0 else pk
        sign[k] = s
        r_start[k] = r
        r += s * dk

    A = A * sign[:, None]
    a0 = a0 * sign[:, None]
    u0 = u0 * sign[:, None]
    r0 = r0 * sign[:, None] + r_start[:, None]
    # The rest segment (column 0) of every move starts at u0 = a0 = 0 exactly, by construction: each row
    # is accumulated on its own from zero, so no rounding from earlier moves can leak into a rest.

    d, A, a0, u0, r0 = (x.ravel() for x in (d, A, a0, u0, r0))
    start = np.concatenate(([0.0], np.cumsum(d)[:-1]))
    j = np.searchsorted(start, t, side="right") - 1
    s = t - start[j]
    dj, Aj = d[j], A[j]
    x = np.clip(np.divide(s, dj, out=np.zeros_like(s), where=dj > 0), 0.0, 1.0)
    half = np.sin(0.5 * np.pi * x)
    a = a0[j] + Aj * half**2  # (1 - cos(pi x)) / 2 = sin^2(pi x / 2)
    u = u0[j] + a0[j] * s + Aj * (s / 2.0 - dj / (2.0 * np.pi) * np.sin(np.pi * x))
    r = r0[j] + u0[j] * s + a0[j] * s**2 / 2.0 + Aj * (s**2 / 4.0 - (dj / np.pi) ** 2 * half**2)
    return r, u, a


# --------------------------------------------------------------------------
# Tumble: the six-position calibration test


def tumble_poses(n_axes: int) -> np.ndarray:
    """Unit 'up' vectors (sensor frame, 3 components) of the tumble's poses for a part with ``n_axes`` axes.

    Axis i reads +1 g when it points up. Three axes: +x, -x, +y, -y, +z, -z (the six-position test).
    Two axes (x, y in the plane of the part): +x, -x, +y, -y, then flat face up and face down, where both
    axes read 0 g. One axis: +x, -x, flat up, flat down.
    """
    if n_axes not in (1, 2, 3):
        raise ValueError(f"n_axes: got {n_axes!r}; accepted: 1, 2 or 3")
    eye = np.eye(3)
    order = {1: [0, 2], 2: [0, 1, 2], 3: [0, 1, 2]}[n_axes]
    return np.array([sign * eye[i] for i in order for sign in (1.0, -1.0)])


def tumble_any_poses(rng: np.random.Generator, count: int) -> np.ndarray:
    """``count`` random 'up' vectors (sensor frame, unit, 3 components): still poses in any orientation.

    Uniform on the sphere, drawn from ``rng`` in chunks of 64 (a shorter run's poses are a prefix of a longer
    one's); a pose within ``TUMBLE_ANY_MIN_TURN_DEG`` of the one before is turned the other way up (negated),
    so that every turn is large enough to be seen as a turn and consecutive poses are distinct.
    """
    chunks = -(-max(1, int(count)) // _CHUNK)
    v = rng.standard_normal((chunks * _CHUNK, 3))[:count]
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    c = np.cos(np.radians(TUMBLE_ANY_MIN_TURN_DEG))
    for k in range(1, len(v)):
        if float(v[k] @ v[k - 1]) > c:
            v[k] = -v[k]
    return v


def tumble_specific_force(t: np.ndarray, n_axes: int, g0: float, poses: np.ndarray | None = None) -> np.ndarray:
    """Specific force [m/s^2] on each of ``n_axes`` axes while the part is turned through still poses.

    ``poses`` (count, 3) are unit 'up' vectors; default :func:`tumble_poses` (the ``tumble`` scenario;
    ``tumble_any`` passes :func:`tumble_any_poses`). Shape (len(t), n_axes). The part starts in the first
    pose, holds each pose ``TUMBLE_HOLD_S`` and turns to the next in ``TUMBLE_TURN_S`` (a rotation in the
    plane of the two up vectors, through their angle), cycling through the poses for as long as ``t`` lasts.
    It turns in place, so its position and velocity stay 0: unlike the other scenarios, a is gravity's
    projection, not du/dt. A turn between opposite poses goes through a perpendicular pose; the up vector
    turns at the raised-cosine rate, so the turn starts and ends smoothly. The poses are exact (a calibration
    cube on a level table, or a part held still in a known orientation for the truth).
    """
    t = np.asarray(t, dtype=np.float64)
    poses = tumble_poses(n_axes) if poses is None else np.asarray(poses, dtype=np.float64)
    period = TUMBLE_HOLD_S + TUMBLE_TURN_S
    k = np.floor(t / period).astype(np.int64)
    s = t - k * period
    cur = poses[k % len(poses)]
    nxt = poses[(k + 1) % len(poses)]
    x = np.clip((s - TUMBLE_HOLD_S) / TUMBLE_TURN_S, 0.0, 1.0)
    w = ((1.0 - np.cos(np.pi * x)) / 2.0)[:, None]
    # a rotation in the plane of the two poses, or through a perpendicular one (180 degrees)
    dot = np.clip(np.sum(cur * nxt, axis=1, keepdims=True), -1.0, 1.0)
    opposite = dot < -1.0 + 1e-9
    perp = nxt - dot * cur
    norm = np.linalg.norm(perp, axis=1, keepdims=True)
    other = np.where(opposite | (norm < 1e-12), np.roll(cur, 1, axis=1), perp / np.maximum(norm, 1e-300))
    angle = np.where(opposite, np.pi, np.arccos(dot)) * w
    up = np.cos(angle) * cur + np.sin(angle) * other
    return g0 * up[:, :n_axes]


# --------------------------------------------------------------------------
# Rest-detection scenarios (issue 23): truth of one line of motion, what the sensor sees beside it, and the
# true rests.

GRADE_MAX_DEG = 4.0  # stop_and_go_graded: the road's grade stays within +-this
GRADE_KNOTS_M = (30.0, 80.0)  # ... and is piecewise linear in position, knots this far apart
HIGHWAY_SPEED = (8.0, 20.0)  # m/s, highway: the speed stays within this band (never stops)
CART_PUSH_M = 5.0  # cart_push: every push moves the cart this far, back and forth


class RestTruth:
    """Truth of a rest scenario: r, u, a (N,) along the line of motion; ``extra`` (N, n) m/s^2 the sensor
    reads beside the motion on each of n axes (a grade's g sin(theta), road or wheel vibration: real
    specific force, but not the motion the filter estimates); ``rest`` (N,) bool, the body is still."""

    def __init__(self, r, u, a, extra, rest):
        self.r, self.u, self.a, self.extra, self.rest = r, u, a, extra, rest


def rest_truth(name: str, t: np.ndarray, ss: np.random.SeedSequence, amax: float, n_axes: int) -> RestTruth:
    """Truth of ``stop_and_go_graded``, ``highway`` or ``cart_push`` at the instants ``t``.

    ``ss`` gives the motion's stream (as the other scenarios use it: the graded run moves exactly as
    ``stop_and_go`` of the same seed) and, spawned from it, the disturbance's; both are drawn in fixed
    chunks, so a shorter run is a prefix of a longer one.

    * ``stop_and_go_graded``: ``stop_and_go``'s motion (same seed, same moves) on a road whose grade theta
      is piecewise linear in position (knots every 30-80 m, values within +-4 degrees); axis x reads
      g sin(theta) on top of the motion, at rest too (the car stops on a slope).
    * ``highway``: a car already at cruise at t = 0 that never stops: u = 14 + 4 sin(2 pi t/P1 + p1) + 2
      sin(2 pi t/P2 + p2) m/s (P1 30-90 s, P2 10-25 s; within 8-20 m/s), plus road vibration on every
      axis: broadband (one pole at 15 Hz), rms 0.03 m/s^2 per m/s of speed (0.24-0.6 m/s^2). It breaks the
      convention that a run starts at rest, as a recording started on the road does; no true rest.
    * ``cart_push``: a hand-pushed cart: a pause of 3-5 s, then pushes of exactly 5 m (u = 5/d (1 - cos 2 pi
      s/d) over d = 5-8 s, alternately forward and back) with pauses of 2-5 s between; rolling vibration
      while it moves (broadband, rms 0.15 m/s^2 per m/s). For an ADXL335-class part at 100 Hz.

    Issue 31's cases (:func:`_speed_profile` chains raised-cosine speed changes and holds; a hold at speed
    reads as still as a stop to an accelerometer, which is the point):

    * ``highway_gnss``: already at 10-18 m/s at t = 0, never stops: holds of 10-60 s at a constant speed,
      then a change to another speed within 8-20 m/s over 10-25 s; road vibration of 0.002 m/s^2 rms per
      m/s (0.016-0.04 m/s^2), below the noise of any shipped model, so a cruise looks still. With fixes
      (FIX_PLANS: 1 Hz, sigma 1 m, a consumer GNSS). No true rest.
    * ``town_drive``: parked 10-20 s, then four legs, each: pull away to 8-16 m/s (at most 2.5 m/s^2), one
      or two holds of 15-40 s with a change to 6-16 m/s between, a last hold, a stop (at most 3 m/s^2);
      3-5 s stops between legs (three short stops), parked for good after the fourth (a run is a prefix of
      a longer one, and any run that outlasts the drive ends parked: the drive takes about 300-650 s, 3-6
      km, see :func:`town_drive_end`). Road vibration as on the highway; fixes every 10 s (sigma 1 m).
    * ``hand_box``: a box moved by hand on a table: a pause of 2-6 s, then moves back and forth (towards
      the start) at peak speeds of 0.15-0.6 m/s (gentle pulses of 0.1-0.6 m/s^2, a steady glide of 0.5-3 s)
      with pauses of 2-6 s; hand tremor while it moves (broadband, 0.03 m/s^2 rms per m/s: a glide, or a
      slow push, reads as still as a pause on an ADXL335-class part). Fixes every 5 s (sigma 2 cm: a camera or a tape).
    * ``tilting_mount``: ``stop_and_go``'s motion (same seed) under a mount whose tilt drifts: on every
      axis the level moves at 0.015-0.11 m/s^2 per second (a new rate every 5-20 s, turning back towards
      level once beyond 0.5 m/s^2), stopped or not.
    """
    t = np.asarray(t, dtype=np.float64)
    rng, rng_x = np.random.default_rng(ss), np.random.default_rng(ss.spawn(1)[0])
    n = len(t)
    extra = np.zeros((n, n_axes))
    if name == "stop_and_go_graded":
        r, u, a = truth("stop_and_go", t, rng, amax)
        extra[:, 0] = 9.80665 * np.sin(_grade(r, rng_x))
        return RestTruth(r, u, a, extra, u == 0)
    if name == "highway":
        P = np.array([rng.uniform(30.0, 90.0), rng.uniform(10.0, 25.0)])
        ph = rng.uniform(0.0, 2 * np.pi, 2)
        amp = np.array([4.0, 2.0])
        w = 2 * np.pi / P
        arg = w * t[:, None] + ph
        u = 14.0 + (amp * np.sin(arg)).sum(axis=1)
        a = (amp * w * np.cos(arg)).sum(axis=1)
        r = 14.0 * t + (amp / w * (np.cos(ph) - np.cos(arg))).sum(axis=1)
        extra = 0.03 * u[:, None] * _vibration(rng_x, n, n_axes, t)
        return RestTruth(r, u, a, extra, np.zeros(n, dtype=bool))
    if name == "cart_push":
        r, u, a = _cart(t, rng)
        extra = 0.15 * np.abs(u)[:, None] * _vibration(rng_x, n, n_axes, t)
        return RestTruth(r, u, a, extra, u == 0)
    if name == "highway_gnss":
        r, u, a = _speed_profile(t, *_highway_segments(rng, float(t[-1]) if n else 0.0))
        extra = ROAD_VIBRATION * u[:, None] * _vibration(rng_x, n, n_axes, t)
        return RestTruth(r, u, a, extra, np.zeros(n, dtype=bool))
    if name == "town_drive":
        r, u, a = _speed_profile(t, *_town_segments(rng, float(t[-1]) if n else 0.0))
        extra = ROAD_VIBRATION * u[:, None] * _vibration(rng_x, n, n_axes, t)
        return RestTruth(r, u, a, extra, u == 0)
    if name == "hand_box":
        moves = _draw_moves(lambda: _draw_hand(rng), float(t[-1]) if n else 0.0)
        r, u, a = _evaluate(moves, t)
        extra = 0.03 * np.abs(u)[:, None] * _vibration(rng_x, n, n_axes, t)
        return RestTruth(r, u, a, extra, u == 0)
    if name == "tilting_mount":
        r, u, a = truth("stop_and_go", t, rng, amax)
        extra = np.stack([_tilt_drift(t, rng_x) for _ in range(n_axes)], axis=1)
        return RestTruth(r, u, a, extra, u == 0)
    raise ValueError(f"name: {name!r} is not one of {', '.join(LINE_SCENARIOS)}")


ROAD_VIBRATION = 0.002  # m/s^2 rms per m/s: highway_gnss, town_drive (below the sensor noise)
TILT_RATE = (0.015, 0.11)  # m/s^2 per s: tilting_mount's level drift
TOWN_LEGS = 4  # town_drive: legs, with a short stop between two


def _speed_profile(t: np.ndarray, d: np.ndarray, u0: np.ndarray, du: np.ndarray):
    """(r, u, a) of a chain of segments: in segment j (duration d_j, start speed u0_j) the speed moves by
    du_j along half a raised cosine, u = u0 + du sin^2(pi x/2), x = s/d (du = 0: a hold). The last segment
    must reach past t[-1]. A segment with u0 = du = 0 has u = a = 0 exactly (a true rest)."""
    start = np.concatenate(([0.0], np.cumsum(d)[:-1]))
    r0 = np.concatenate(([0.0], np.cumsum(u0 * d + du * d / 2.0)[:-1]))
    j = np.clip(np.searchsorted(start, t, side="right") - 1, 0, len(d) - 1)
    s = t - start[j]
    dj, duj = d[j], du[j]
    x = np.clip(s / dj, 0.0, 1.0)
    u = u0[j] + duj * np.sin(0.5 * np.pi * x) ** 2
    a = duj * np.pi / (2.0 * dj) * np.sin(np.pi * x)
    r = r0[j] + u0[j] * s + duj * (s / 2.0 - dj / (2.0 * np.pi) * np.sin(np.pi * x))
    return r, u, a


def _chain(steps: list[tuple[float, float]], u_start: float, t_end: float):
    """Segment arrays (d, u0, du) of ``steps`` = [(duration, speed at its end), ...] from ``u_start``, the
    last speed held until past ``t_end``."""
    d, u0, du = [], [], []
    u = u_start
    for dur, target in steps:
        d.append(dur)
        u0.append(u)
        du.append(target - u)
        u = target
    d.append(max(1.0, t_end + 1.0 - sum(d)))
    u0.append(u)
    du.append(0.0)
    return np.array(d), np.array(u0), np.array(du)


def _highway_segments(rng: np.random.Generator, t_end: float):
    u = cur = rng.uniform(10.0, 18.0)
    steps: list[tuple[float, float]] = []
    covered = 0.0
    while covered <= t_end + 1.0:
        hold = rng.uniform(10.0, 60.0, _CHUNK)
        speed = rng.uniform(*HIGHWAY_SPEED, _CHUNK)
        change = rng.uniform(10.0, 25.0, _CHUNK)
        for h, v, c in zip(hold, speed, change, strict=True):
            steps += [(h, cur), (c, v)]
            cur = v
        covered += float(hold.sum() + change.sum())
    return _chain(steps, u, t_end)


def _town_steps(rng: np.random.Generator) -> list[tuple[float, float]]:
    """The drive of ``town_drive``, independent of the run's length: [(duration, speed at its end), ...]."""
    steps = [(rng.uniform(10.0, 20.0), 0.0)]
    for leg in range(TOWN_LEGS):
        v = rng.uniform(8.0, 16.0)
        steps.append((max(rng.uniform(6.0, 12.0), v * np.pi / (2 * 2.5)), v))  # peak a = dv pi / (2 d)
        for _ in range(int(rng.integers(1, 3))):
            hold, v_next, change = rng.uniform(15.0, 40.0), rng.uniform(6.0, 16.0), rng.uniform(6.0, 12.0)
            steps += [(hold, v), (max(change, abs(v_next - v) * np.pi / (2 * 2.5)), v_next)]
            v = v_next
        hold, brake, stop = rng.uniform(15.0, 40.0), rng.uniform(5.0, 10.0), rng.uniform(3.0, 5.0)
        steps += [(hold, v), (max(brake, v * np.pi / (2 * 3.0)), 0.0)]
        if leg < TOWN_LEGS - 1:
            steps.append((stop, 0.0))
    return steps


def _town_segments(rng: np.random.Generator, t_end: float):
    return _chain(_town_steps(rng), 0.0, t_end)


def town_drive_end(ss: np.random.SeedSequence) -> float:
    """When ``town_drive`` parks for good (s) for the motion stream ``ss`` (a run's
    ``np.random.SeedSequence(seed).spawn(1)[0]``, see accelnav.hil_sim.sim.sensor)."""
    return float(sum(d for d, _ in _town_steps(np.random.default_rng(ss))))


def _draw_hand(rng: np.random.Generator) -> dict[str, np.ndarray]:
    n = _CHUNK
    rest = rng.uniform(2.0, 6.0, n)
    v = rng.uniform(0.15, 0.6, n)
    A = rng.uniform(0.1, 0.6, n)
    e, f = _pulse_for(v, A, rng.uniform(0.3, 1.0, n))
    c = rng.uniform(0.5, 3.0, n)
    pref = rng.choice([-1.0, 1.0], n)
    return dict(rest=rest, A1=A, e1=e, f1=f, c=c, A2=A, e2=e, f2=f, pref=pref)


def _tilt_drift(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N,) level error [m/s^2]: piecewise linear from 0, a rate of TILT_RATE (either sign) per 5-20 s
    segment, turned back towards 0 while beyond 0.5 m/s^2. Segments drawn in chunks (prefix-consistent)."""
    t_end = float(t[-1]) if len(t) else 0.0
    knots_t, knots_v = [0.0], [0.0]
    while knots_t[-1] <= t_end + 1.0:
        dur = rng.uniform(5.0, 20.0, _CHUNK)
        rate = rng.uniform(*TILT_RATE, _CHUNK)
        sign = rng.choice([-1.0, 1.0], _CHUNK)
        for d, q, s in zip(dur, rate, sign, strict=True):
            v = knots_v[-1]
            s = -np.sign(v) if abs(v) > 0.5 else s
            knots_t.append(knots_t[-1] + d)
            knots_v.append(v + s * q * d)
    return np.interp(t, knots_t, knots_v)


def _grade(r: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """theta(r) [rad]: piecewise linear in position, knots 30-80 m apart from -2 km, within +-4 degrees."""
    lo = min(-2000.0, float(np.min(r, initial=0.0)) - 100.0)
    hi = max(2000.0, float(np.max(r, initial=0.0)) + 100.0)
    knots = [lo]
    while knots[-1] < hi:
        knots.extend((knots[-1] + np.cumsum(rng.uniform(*GRADE_KNOTS_M, _CHUNK))).tolist())
    theta = rng.uniform(-1.0, 1.0, len(knots)) * np.radians(GRADE_MAX_DEG)
    return np.interp(r, knots, theta)


def _vibration(rng: np.random.Generator, n: int, n_axes: int, t: np.ndarray) -> np.ndarray:
    """(n, n_axes) unit-rms broadband noise: white through one pole at 15 Hz, stationary from the start."""
    import scipy.signal as sig

    dt = float(t[1] - t[0]) if n > 1 else 0.01
    rho = np.exp(-2 * np.pi * 15.0 * dt)
    drive = rng.standard_normal((n, n_axes))
    drive[1:] *= np.sqrt(1 - rho * rho)
    return sig.lfilter([1.0], [1.0, -rho], drive, axis=0)


def _cart(t: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t_end = float(t[-1]) if len(t) else 0.0
    pauses, pushes = [rng.uniform(3.0, 5.0)], []
    total = pauses[0]
    while total <= t_end + 1.0:
        d = rng.uniform(5.0, 8.0, _CHUNK)
        p = rng.uniform(2.0, 5.0, _CHUNK)
        pushes.extend(d.tolist())
        pauses.extend(p.tolist())
        total += float(d.sum() + p.sum())
    d = np.array(pushes)
    start = pauses[0] + np.concatenate(([0.0], np.cumsum(d + np.array(pauses[1 : len(d) + 1]))[:-1]))
    sign = np.where(np.arange(len(d)) % 2 == 0, 1.0, -1.0)
    i = np.clip(np.searchsorted(start, t, side="right") - 1, 0, len(d) - 1)
    s = t - start[i]
    on = (s >= 0) & (s < d[i])
    x = np.clip(s / d[i], 0.0, 1.0)
    L, di, w = CART_PUSH_M * sign[i], d[i], 2 * np.pi * np.clip(s / d[i], 0.0, 1.0)
    u = np.where(on, L / di * (1 - np.cos(w)), 0.0)
    a = np.where(on, 2 * np.pi * L / di**2 * np.sin(w), 0.0)
    done = np.where(s >= 0, L * np.where(on, x - np.sin(w) / (2 * np.pi), 1.0), 0.0)
    base = np.concatenate(([0.0], np.cumsum(CART_PUSH_M * sign)))[i]  # where push i starts
    return base + done, u, a
