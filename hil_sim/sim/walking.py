"""A foot-mounted sensor during a walk: the ``walking`` scenario.

The sensor sits on a foot; its two horizontal axes are taken as already
rotated to a level frame with gravity removed (what a user gets from an IMU's
attitude solution), so they measure the foot's horizontal acceleration plus
whatever that rotation got wrong.

Gait (one stride = one stance then one swing, SI units)
-------------------------------------------------------
* cycle time 0.95-1.10 s (about 1 Hz cadence); stance 30-40 % of the cycle
  (0.29-0.44 s), swing the rest;
* stride length L 1.2-1.5 m, the foot's displacement over one swing;
* heading: a small random change at every stride (sigma 3 degrees), and every
  6-12 strides a turn of 60-120 degrees either way spread over three strides;
* swing profile along the heading, x = s/d in [0, 1] over a swing of length d:

      a = 2 pi L'/d^2 sin(2 pi x),  u = L'/d (1 - cos(2 pi x)),  r = L' (x - sin(2 pi x)/(2 pi))

  so velocity and acceleration are zero at both ends (the foot lands and
  leaves at rest, peak speed 2 L'/d, about 4 m/s, peak acceleration about 2 g);
* shocks: at toe-off (the first tau of the swing) and at heel strike (the
  last tau) a pulse along the heading, with y = 2 pi s/tau,

      a = P c (sin y - sin(2 y)/2),  c = 1/1.299 (so that max a = P),

  tau 30-50 ms, |P| 8-16 g (capped at 0.8 of the sensor's full scale, so that with the
  swing's 2 g it stays inside), + at
  toe-off and - at heel strike. At 100 Hz a pulse spans three to five
  samples; shorter ones (20-40 ms) alias so badly that even the smoother
  given the true stances misses strides by 5-7 % (velocity integrated over
  two or three samples of a 16 g pulse): a sample rate of 200 Hz or more
  suits a foot. a and its derivative are zero at both ends
  of a pulse, its area is zero (the velocity comes back to where it was) and
  it moves the foot by P c tau^2 3/(8 pi); the main profile's
  L' = L - (sum of the two pulse moves), so the stride is exactly L;
* stance: r constant, u = a = 0 exactly.

Tilt error: the level-frame rotation is off by a slowly varying tilt
theta_j(t) = theta0_j + A_j sin(2 pi t/P_j + phi_j) per axis (theta0 up to
0.5 degrees, A up to 0.5 degrees, P 20-60 s), which leaks g sin(theta_j) into
the horizontal axis: a sensor error, not motion, returned as ``leak``.

Level drift (``walking_drift``, :func:`level_drift`): a cheap attitude solution whose level frame
wanders, so that the gravity leak grows from about 0.2 m/s^2 at the start to 0.9 m/s^2 after a minute,
in a direction that turns slowly; added on top of the tilt leak above.

Random numbers: the tilt parameters first (a fixed count), then strides in
chunks of a fixed size, so a shorter run is a prefix of a longer one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

G0 = 9.80665
_CHUNK = 64  # strides drawn per batch of random numbers
_C = 1.0 / (np.sin(2 * np.pi / 3) - 0.5 * np.sin(4 * np.pi / 3))  # pulse shape's peak normalisation


@dataclass(frozen=True)
class Walk:
    """Truth of a walk on the sample instants t: (N, 2) horizontal r, u, a, leak; (N,) stance mask."""

    r: np.ndarray
    u: np.ndarray
    a: np.ndarray
    leak: np.ndarray  # m/s^2, gravity leaking through the tilt error (sensor error, not motion)
    stance: np.ndarray  # bool, the foot is on the ground (u == a == 0 exactly)


# (cycle time s, stance share of the cycle, stride length m, shock peak g) ranges of a gait
GAITS = {
    "normal": ((0.95, 1.10), (0.30, 0.40), (1.2, 1.5), (8.0, 16.0)),
    "fast": ((0.70, 0.80), (0.20, 0.26), (1.2, 1.5), (8.0, 16.0)),
    # a jog: 0.47-0.56 s swings of 1.8-2.1 m (the foot at up to 9 m/s, 6.5 g), so smaller shocks keep the sum
    # inside a 16 g part
    "jog": ((0.68, 0.78), (0.28, 0.34), (1.8, 2.1), (4.0, 8.0)),
}
JOG_LEAK = (3.0, 0.7, (3.0, 6.0))  # jogging's level leak: mean size and swing (m/s^2), the swing's period (s)
STILL_START = (0.2, (2.0, 4.0), 0.02)  # walking_still_start: jostle (s), stand (s), jostle's move (m)


def _draw_strides(rng: np.random.Generator, amax: float, gait: str = "normal") -> dict[str, np.ndarray]:
    n = _CHUNK
    cycle_range, frac_range, length_range, peak_range = GAITS[gait]
    cycle = rng.uniform(*cycle_range, n)
    frac = rng.uniform(*frac_range, n)
    length = rng.uniform(*length_range, n)
    turn_every = rng.integers(6, 13, n)
    turn = rng.uniform(np.pi / 3, 2 * np.pi / 3, n) * rng.choice([-1.0, 1.0], n)
    wiggle = rng.normal(0.0, np.radians(3.0), n)
    peak = np.minimum(rng.uniform(*peak_range, (n, 2)) * G0, 0.8 * amax)
    tau = rng.uniform(0.030, 0.050, (n, 2))
    return dict(
        cycle=cycle, frac=frac, length=length, turn_every=turn_every, turn=turn, wiggle=wiggle, peak=peak, tau=tau
    )


def walk(t: np.ndarray, rng: np.random.Generator, amax: float, gait: str = "normal") -> Walk:
    """The walk at the instants ``t`` (s, from 0); ``amax`` is the sensor's full scale in m/s^2.

    ``gait``: "normal" (the module docstring), "fast" (cycle 0.70-0.80 s, stance 20-26 % of it:
    0.14-0.21 s on the ground, the short stances a brisk walker's foot-flat phase gives) or "jog" (see
    GAITS).
    """
    t = np.asarray(t, dtype=np.float64)
    n = len(t)
    theta0 = np.radians(rng.uniform(-0.5, 0.5, 2))
    amp = np.radians(rng.uniform(0.0, 0.5, 2))
    period = rng.uniform(20.0, 60.0, 2)
    phase = rng.uniform(0.0, 2 * np.pi, 2)
    leak = G0 * np.sin(theta0 + amp * np.sin(2 * np.pi * t[:, None] / period + phase))

    # strides until they cover the run
    chunks = []
    covered = 0.0
    t_end = float(t[-1]) if n else 0.0
    while covered <= t_end + 2.0:
        c = _draw_strides(rng, amax, gait)
        covered += float(c["cycle"].sum())
        chunks.append(c)
    s = {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]}
    m = len(s["cycle"])

    # heading: a wiggle per stride plus turns spread over three strides
    dpsi = s["wiggle"].copy()
    k = 0
    while k < m:
        k += int(s["turn_every"][k])
        if k + 3 <= m:
            dpsi[k : k + 3] += s["turn"][k] / 3.0
        k += 3
    psi = np.cumsum(dpsi)

    stance_d = s["cycle"] * s["frac"]
    swing_d = s["cycle"] - stance_d
    start = np.concatenate(([0.0], np.cumsum(s["cycle"])[:-1]))  # stance start of stride i
    swing0 = start + stance_d
    pulse_dr = _C * s["peak"] * s["tau"] ** 2 * 3 / (8 * np.pi) * np.array([1.0, -1.0])  # toe-off +, heel strike -
    main_len = s["length"] - pulse_dr.sum(axis=1)
    direction = np.stack([np.cos(psi), np.sin(psi)], axis=1)
    foot = np.concatenate((np.zeros((1, 2)), np.cumsum(s["length"][:, None] * direction, axis=0)))  # at stance i

    i = np.clip(np.searchsorted(start, t, side="right") - 1, 0, m - 1)
    q = t - swing0[i]  # time into the swing (< 0: stance)
    in_swing = q >= 0.0
    d = swing_d[i]
    x = np.clip(q / d, 0.0, 1.0)
    w = 2 * np.pi * x
    L = main_len[i]
    # along-track: the main profile ...
    r1 = np.where(in_swing, L * (x - np.sin(w) / (2 * np.pi)), 0.0)
    u1 = np.where(in_swing, L / d * (1 - np.cos(w)), 0.0)
    a1 = np.where(in_swing, 2 * np.pi * L / d**2 * np.sin(w), 0.0)
    # ... plus the toe-off pulse (first tau of the swing) and the heel-strike pulse (last tau)
    for p, (sign, t0) in enumerate(((1.0, np.zeros_like(q)), (-1.0, d - s["tau"][i, 1]))):
        P, tau = sign * s["peak"][i, p], s["tau"][i, p]
        sp = np.clip(q - t0, 0.0, tau)
        wp = 2 * np.pi * sp / tau
        on = in_swing & (q >= t0) & (q < t0 + tau)
        done = in_swing & (q >= t0 + tau)
        y = sp / tau
        a1 = a1 + np.where(on, _C * P * (np.sin(wp) - 0.5 * np.sin(2 * wp)), 0.0)
        u_p = _C * P * tau * ((1 - np.cos(wp)) / (2 * np.pi) - (1 - np.cos(2 * wp)) / (8 * np.pi))
        u1 = u1 + np.where(on, u_p, 0.0)
        r_p = (
            _C
            * P
            * tau**2
            * ((y - np.sin(wp) / (2 * np.pi)) / (2 * np.pi) - (y - np.sin(2 * wp) / (4 * np.pi)) / (8 * np.pi))
        )
        r1 = r1 + np.where(on | done, r_p, 0.0)
    dirs = direction[i]
    r = foot[i] + r1[:, None] * dirs
    u = u1[:, None] * dirs
    a = a1[:, None] * dirs
    return Walk(r=r, u=u, a=a, leak=leak, stance=~in_swing)


def level_drift(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 2) gravity leak [m/s^2] of a drifting level frame: |leak| = 0.2 + 0.7 min(t / 60 s, 1), its
    direction starting at a random angle and turning by 30-90 degrees a minute (drawn from ``rng``)."""
    t = np.asarray(t, dtype=np.float64)
    angle0 = rng.uniform(0.0, 2 * np.pi)
    turn = np.radians(rng.uniform(30.0, 90.0)) * rng.choice([-1.0, 1.0]) / 60.0
    size = 0.2 + 0.7 * np.minimum(t / 60.0, 1.0)
    angle = angle0 + turn * t
    return np.stack([size * np.cos(angle), size * np.sin(angle)], axis=1)


def scenario_walk(name: str, t: np.ndarray, ss: np.random.SeedSequence, amax: float) -> Walk:
    """The walk of scenario ``name`` (``walking`` or one of trajectories.WALK_SCENARIOS) from the motion
    stream ``ss``: the strides come from ``ss`` itself (a variant walks as ``walking`` of the same seed
    does, with its gait), what a variant adds from ``ss.spawn(1)[0]``.

    * ``walking_drift``: the normal walk plus :func:`level_drift`.
    * ``walking_fast``: the fast gait.
    * ``walking_still_start``: the wearer stands still 2-4 s before walking, but the foot is jostled in the
      first 0.2 s (a 2 cm shuffle along the first heading, u = a = 0 at both ends): the first stand begins
      0.2 s in. The walk proper is the normal walk shifted by the jostle and the stand.
    * ``jogging``: the jog gait with a level frame leaking 3 +- 0.7 m/s^2 (:func:`jog_leak`), on top of the
      tilt leak.
    """
    t = np.asarray(t, dtype=np.float64)
    rng = np.random.default_rng(ss)
    if name == "walking_still_start":
        jostle, stand_range, move = STILL_START
        extra = np.random.default_rng(ss.spawn(1)[0])
        t0 = jostle + extra.uniform(*stand_range)
        w = walk(t - t0, rng, amax)  # stands (first stance) until t0, then walks
        x = np.clip(t / jostle, 0.0, 1.0)
        on = t < jostle
        w2 = 2 * np.pi * x
        first = _first_heading(w)
        r1 = move * (x - np.sin(w2) / (2 * np.pi))
        u1 = np.where(on, move / jostle * (1 - np.cos(w2)), 0.0)
        a1 = np.where(on, 2 * np.pi * move / jostle**2 * np.sin(w2), 0.0)
        return Walk(
            r=w.r + r1[:, None] * first,
            u=w.u + u1[:, None] * first,
            a=w.a + a1[:, None] * first,
            leak=w.leak,
            stance=w.stance & ~on,
        )
    gait = {"walking_fast": "fast", "jogging": "jog"}.get(name, "normal")
    w = walk(t, rng, amax, gait)
    if name == "walking_drift":
        return replace(w, leak=w.leak + level_drift(t, np.random.default_rng(ss.spawn(1)[0])))
    if name == "jogging":
        return replace(w, leak=w.leak + jog_leak(t, np.random.default_rng(ss.spawn(1)[0])))
    return w


def _first_heading(w: Walk) -> np.ndarray:
    """Unit direction of the walk's first swing (x if the run ends before one)."""
    moving = np.flatnonzero(np.linalg.norm(w.u, axis=1) > 0)
    v = w.u[moving[0]] if len(moving) else np.array([1.0, 0.0])
    return v / np.linalg.norm(v)


def jog_leak(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 2) gravity leak [m/s^2] of a jogger's level frame: size 3 + 0.7 sin(2 pi t/P + p) (JOG_LEAK: P 3-6
    s, so the level moves by up to 1 m/s^2 from one stance to the next), direction from a random angle turning
    30-90 degrees a minute (drawn from ``rng``)."""
    t = np.asarray(t, dtype=np.float64)
    mean, swing, periods = JOG_LEAK
    angle0 = rng.uniform(0.0, 2 * np.pi)
    turn = np.radians(rng.uniform(30.0, 90.0)) * rng.choice([-1.0, 1.0]) / 60.0
    period, phase = rng.uniform(*periods), rng.uniform(0.0, 2 * np.pi)
    size = mean + swing * np.sin(2 * np.pi * t / period + phase)
    angle = angle0 + turn * t
    return np.stack([size * np.cos(angle), size * np.sin(angle)], axis=1)
