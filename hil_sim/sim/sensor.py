"""What the MCU sees: truth + bias + noise through the sensor's output stage and its read-out.

:func:`simulate` returns a :class:`SimRun`: the truth of every axis (r, u, a,
eps), the raw samples the firmware would read (ADC codes, or duty-cycle timer
counts T1/T2), the samples flagged as clipped, and the acceleration those
raw samples convert to (the filter's measurement z), computed with the very
conversion the rest of accelnav uses (:func:`codegen.design.input_conversion`).

Per axis, in this order (SI units; G0 = 9.80665 m/s^2 per g):

1. Bias, eps(t) = c1 (1 - exp(-t/T)) + c2 + g(t), where g is a first-order
   Gauss-Markov process sampled exactly:
   g[k+1] = exp(-Ts/T) g[k] + w[k], w ~ N(0, Ts sigma_eps^2), g[0] = 0, or
   g[0] ~ N(0, initial_sigma[3]^2) with ``initial_random=True`` (the bias
   then starts as a draw from the filter's prior on eps).
2. Sensor noise n: white noise of density d [g/sqrt(Hz)] through the output
   filter, one pole at B = bandwidth_hz. Sampled, it is exactly AR(1):
   n[k+1] = rho n[k] + sqrt(1 - rho^2) sigma v[k], rho = exp(-2 pi B Ts),
   sigma^2 = (d G0)^2 (pi/2) B, started stationary (n[0] ~ N(0, sigma^2)).
   The truth acceleration is *not* passed through that filter: the filter
   and the simulator both take a as seen by the sensor, so a smooth truth
   stays comparable sample by sample (the one-pole lag of a 50 Hz filter is
   3 ms, below the sample period).
3. Read-out of m = a + eps + n:
   * analog: V = zero_g + sensitivity m / G0, clipped to [0, supply_v];
     code = round(V / adc_ref_v * 2**adc_bits), clipped to
     [0, 2**adc_bits - 1] (an ideal mid-tread ADC, no half-LSB offset,
     matching ``AnalogConversion.accel``);
   * duty cycle: duty = zero_g + sensitivity m / G0, clipped to [0, 1];
     T2 = the nominal period in counts, with +-1 count of jitter on 10 % of
     the samples (5 % each way); T1 = round(duty T2).

Random streams: ``np.random.SeedSequence(seed).spawn(4)`` gives one stream
for the motion (shared by all axes) and one per model axis (by its index in
the model), which is split again into bias walk, bias start, noise and
jitter. So the same seed gives the same run, a shorter run is a prefix of a
longer one, simulating a subset of the axes gives the same columns, and
``initial_random`` changes nothing but the bias start.

The ``tumble`` scenario (the six-position calibration test) is the exception: each
axis sees its own share of gravity as the part is turned through the poses of
:func:`accelnav.hil_sim.sim.trajectories.tumble_poses`, and r = u = 0. ``tumble_any``
does the same through random still orientations
(:func:`accelnav.hil_sim.sim.trajectories.tumble_any_poses`, drawn from the motion
stream: one per ``TUMBLE_HOLD_S + TUMBLE_TURN_S``), for the gravity-magnitude
calibration of a 3-axis part (a 2-axis part sees only their in-plane components).

Motion of several axes: one trajectory is drawn and axis i of the model sees
it scaled by AXIS_GAIN[i] = (1.0, -0.8, 0.6)[i], as a rigid body moving along
a fixed direction would. Rests, and rest times, are thus common to all axes.
The ``walking`` scenario is the exception: it is a horizontal walk
(:mod:`accelnav.hil_sim.sim.walking`), axes 0 and 1 see its two horizontal
components plus the gravity leaking through its tilt error, a third axis sees
no motion, and the run carries the true stance mask (``stance``) from which
stride lengths are scored.

The rest-detection scenarios (:data:`accelnav.hil_sim.sim.trajectories.REST_SCENARIOS`: ``walking_drift``,
``walking_fast``, ``walking_still_start``, ``jogging``, ``stop_and_go_graded``, ``highway``, ``cart_push``,
``highway_gnss``, ``town_drive``, ``hand_box``, ``tilting_mount``) carry the true rests as ``rest`` (and the
walks their ``stance`` as well); what the sensor reads beside the motion (a drifting level, a grade,
vibration) is added like the walk's tilt leak, to the measurement and not to the truth. Those of
:data:`~accelnav.hil_sim.sim.trajectories.FIX_PLANS` also carry position fixes, ``fixes`` (run file key
``sim_fixes``): :func:`scenario_fixes`, from a fifth stream of the seed (``SeedSequence(seed).spawn(5)[4]``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from accelnav.lazy import lazy_module
from accelnav.model.design import input_conversion
from accelnav.model.load import G0, Model

from .trajectories import (
    FIX_PLANS,
    REST_SCENARIOS,
    TUMBLE_HOLD_S,
    TUMBLE_TURN_S,
    WALK_SCENARIOS,
    require_scenario,
    rest_truth,
    truth,
    tumble_any_poses,
    tumble_specific_force,
)

signal = lazy_module("scipy.signal")

AXIS_GAIN = (1.0, -0.8, 0.6)  # motion seen by model axis 0, 1, 2 (relative to the drawn trajectory)
MAX_AXES = len(AXIS_GAIN)
JITTER_FRACTION = 0.10  # share of duty-cycle samples whose T2 is off by one count


@dataclass(frozen=True, eq=False)
class SimRun:
    """One simulated recording. Arrays are (N,) or (N, n_axes), read-only.

    t [s]; truth r [m], u [m/s], a [m/s^2], eps [m/s^2]; raw input ``code``
    (analog, int32) or ``t1``, ``t2`` (duty cycle, int32, timer counts);
    ``clipped`` (bool, the conversion's verdict: rail or bad capture);
    ``accel`` [m/s^2] = the conversion of the raw input (the filter's z).
    Column j belongs to the model axis named ``axis_names[j]``.
    """

    model: Model
    scenario: str
    seed: int
    t: np.ndarray
    axis_names: tuple[str, ...]
    r: np.ndarray
    u: np.ndarray
    a: np.ndarray
    eps: np.ndarray
    code: np.ndarray | None
    t1: np.ndarray | None
    t2: np.ndarray | None
    clipped: np.ndarray
    accel: np.ndarray
    initial_random: bool = field(default=True)
    stance: np.ndarray | None = None  # (N,) bool, walking only: the foot is on the ground
    rest: np.ndarray | None = None  # (N,) bool, rest scenarios only: the true rests (the body is still)
    fixes: np.ndarray | None = None  # (M, 4) [t, column, r, sigma], scenarios of FIX_PLANS only: position fixes

    @property
    def n_axes(self) -> int:
        return len(self.axis_names)

    def column(self, axis: str | int) -> int:
        """Column of ``axis`` (a name, or a column index) in the (N, n_axes) arrays."""
        if isinstance(axis, int) and not isinstance(axis, bool) and -self.n_axes <= axis < self.n_axes:
            return axis % self.n_axes
        if axis in self.axis_names:
            return self.axis_names.index(axis)
        raise ValueError(f"axis: got {axis!r}; accepted: one of {list(self.axis_names)} or a column index")

    def state(self, axis: str | int) -> np.ndarray:
        """(N, 4) true state [r, u, a, eps] of one axis, the filter's x."""
        j = self.column(axis)
        return np.stack([self.r[:, j], self.u[:, j], self.a[:, j], self.eps[:, j]], axis=1)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The run as plain arrays (NPZ-ready, no pickled objects); the model is not included."""
        d = {
            "t": self.t,
            "axis_names": np.array(self.axis_names, dtype=str),
            "r": self.r,
            "u": self.u,
            "a": self.a,
            "eps": self.eps,
            "clipped": self.clipped,
            "accel": self.accel,
            "scenario": np.array(self.scenario, dtype=str),
            "seed": np.array(self.seed, dtype=np.int64),
            "initial_random": np.array(self.initial_random, dtype=bool),
        }
        if self.stance is not None:
            d["stance"] = self.stance
        if self.rest is not None:
            d["rest"] = self.rest
        if self.fixes is not None:
            d["sim_fixes"] = self.fixes
        if self.code is not None:
            d["code"] = self.code
        elif self.t1 is not None:
            d["t1"] = self.t1
            d["t2"] = self.t2
        return {k: np.array(v) for k, v in d.items()}

    @classmethod
    def from_arrays(cls, model: Model, d: dict[str, np.ndarray]) -> SimRun:
        """Rebuild a run from :meth:`to_arrays` output (e.g. read from an NPZ) and its model.

        Checks the keys, shapes, axis names and that ``accel`` and ``clipped``
        are what ``model`` converts the raw input to; raises ValueError otherwise.
        """
        raw_keys = {"analog": ("code",), "duty_cycle": ("t1", "t2"), "calibrated": ()}[model.sensor.kind]
        need = ("t", "axis_names", "r", "u", "a", "eps", "clipped", "accel", "scenario", "seed", *raw_keys)
        missing = [k for k in need if k not in d]
        if missing:
            raise ValueError(f"d: keys {missing} are missing; a {model.sensor.kind} run needs: {', '.join(need)}")
        t = np.asarray(d["t"], dtype=np.float64)
        names = tuple(str(s) for s in np.asarray(d["axis_names"]).reshape(-1))
        known = [ax.name for ax in model.axes]
        if not names or any(n not in known for n in names):
            raise ValueError(f"axis_names: got {list(names)}; accepted: names of the model's axes {known}")
        shape = (t.size, len(names))
        arrays = {}
        for key, dtype in [(k, np.float64) for k in ("r", "u", "a", "eps", "accel")] + [
            ("clipped", bool),
            *[(k, np.int32) for k in raw_keys],
        ]:
            arr = np.asarray(d[key])
            if arr.shape != shape:
                raise ValueError(f"{key}: shape {arr.shape}; expected {shape} (len(t), len(axis_names))")
            arrays[key] = _readonly(arr.astype(dtype))
        for j, name in enumerate(names):
            conv = input_conversion(model, name)
            raw = [arrays[k][:, j] for k in raw_keys] or [arrays["accel"][:, j] / conv.scale]
            if not np.allclose(conv.accel(*raw), arrays["accel"][:, j], rtol=1e-12, atol=1e-12):
                raise ValueError(f"accel: axis {name!r} does not match its raw input under model {model.name!r}")
            if not np.array_equal(conv.clipped(*raw), arrays["clipped"][:, j]):
                raise ValueError(f"clipped: axis {name!r} does not match its raw input under model {model.name!r}")
        return cls(
            model=model,
            scenario=str(np.asarray(d["scenario"])[()]),
            seed=int(np.asarray(d["seed"])[()]),
            t=_readonly(t),
            axis_names=names,
            r=arrays["r"],
            u=arrays["u"],
            a=arrays["a"],
            eps=arrays["eps"],
            code=arrays.get("code"),
            t1=arrays.get("t1"),
            t2=arrays.get("t2"),
            clipped=arrays["clipped"],
            accel=arrays["accel"],
            initial_random=bool(np.asarray(d.get("initial_random", True))[()]),
            stance=_readonly(np.asarray(d["stance"], dtype=bool)) if "stance" in d else None,
            rest=_readonly(np.asarray(d["rest"], dtype=bool)) if "rest" in d else None,
            fixes=_readonly(np.asarray(d["sim_fixes"], dtype=np.float64).reshape(-1, 4)) if "sim_fixes" in d else None,
        )


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


# --------------------------------------------------------------------------


def simulate(
    model: Model,
    scenario: str,
    duration_s: float,
    seed: int,
    *,
    axes: Sequence[str | int] | None = None,
    initial_random: bool = True,
) -> SimRun:
    """Simulate ``duration_s`` seconds of ``scenario`` on ``model``'s sensor.

    Samples are at t = k Ts for 0 <= t < duration_s (Ts = 1/rate_hz).
    ``axes`` selects model axes by name or index (default: all, in model
    order). ``seed`` is a non-negative integer. See the module docstring for
    the sensor model and the random streams.
    """
    require_scenario(scenario)
    max_run = model.ranges.max_run_s
    if (
        isinstance(duration_s, bool)
        or not isinstance(duration_s, (int, float, np.integer, np.floating))
        or not 0.0 < float(duration_s) <= max_run
    ):
        raise ValueError(
            f"duration_s: got {duration_s!r}; accepted: seconds in (0, {max_run:g}] (model ranges.max_run_s)"
        )
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: got {seed!r}; accepted: an integer >= 0")
    if not isinstance(initial_random, bool):
        raise ValueError(f"initial_random: got {initial_random!r}; accepted: True or False")
    indices = _axis_indices(model, axes)

    n = max(1, math.ceil(float(duration_s) * model.rate_hz - 1e-9))
    t = np.arange(n, dtype=np.float64) / model.rate_hz
    motion_ss, *axis_ss, fix_ss = np.random.SeedSequence(int(seed)).spawn(2 + MAX_AXES)
    stance = turned = rest = extra = None
    if scenario == "walking" or scenario in WALK_SCENARIOS:
        from .walking import scenario_walk

        w = scenario_walk(scenario, t, motion_ss, model.max_accel_m_s2)
        stance = w.stance
        rest = None if scenario == "walking" else stance
    elif scenario in REST_SCENARIOS:
        v = rest_truth(scenario, t, motion_ss, model.max_accel_m_s2, MAX_AXES)
        r1, u1, a1, extra, rest = v.r, v.u, v.a, v.extra, v.rest
    elif scenario == "tumble":
        r1 = u1 = a1 = np.zeros_like(t)
        turned = tumble_specific_force(t, len(model.axes), G0)
    elif scenario == "tumble_any":
        r1 = u1 = a1 = np.zeros_like(t)
        count = int(t[-1] // (TUMBLE_HOLD_S + TUMBLE_TURN_S)) + 2
        poses = tumble_any_poses(np.random.default_rng(motion_ss), count)
        turned = tumble_specific_force(t, len(model.axes), G0, poses)
    else:
        r1, u1, a1 = truth(scenario, t, np.random.default_rng(motion_ss), model.max_accel_m_s2)

    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("r", "u", "a", "eps", "raw0", "raw1", "clipped", "accel")}
    for i in indices:
        walk_ss, start_ss, noise_ss, jitter_ss = axis_ss[i].spawn(4)
        eps = bias(model, i, t, np.random.default_rng(walk_ss), np.random.default_rng(start_ss), initial_random)
        noise = sensor_noise(model, n, np.random.default_rng(noise_ss))
        if stance is not None:  # walking: horizontal components, tilt leak; a third axis does not move
            zero = np.zeros(n)
            r_i, u_i, a_i, leak = (x[:, i] if i < 2 else zero for x in (w.r, w.u, w.a, w.leak))
        elif turned is not None:  # tumble: the specific force of each pose; no motion of the part's centre
            r_i, u_i, a_i, leak = np.zeros(n), np.zeros(n), turned[:, i], 0.0
        else:
            gain = AXIS_GAIN[i]
            r_i, u_i, a_i, leak = gain * r1, gain * u1, gain * a1, 0.0
            if extra is not None:  # a grade's leak, vibration: read by the sensor, not motion
                leak = extra[:, i]
        a = a_i
        raw = read_out(model, i, a + eps + leak + noise, np.random.default_rng(jitter_ss))
        conv = input_conversion(model, i)
        cols["r"].append(r_i)
        cols["u"].append(u_i)
        cols["a"].append(a)
        cols["eps"].append(eps)
        for k, v in enumerate(raw):
            cols[f"raw{k}"].append(v)
        cols["clipped"].append(conv.clipped(*raw))
        cols["accel"].append(conv.accel(*raw))

    def stack(key: str, dtype) -> np.ndarray:
        return _readonly(np.stack(cols[key], axis=1).astype(dtype, copy=False))

    analog = model.sensor.kind == "analog"
    duty = model.sensor.kind == "duty_cycle"
    r_all = stack("r", np.float64)
    fixes = scenario_fixes(scenario, t, r_all, indices, fix_ss) if scenario in FIX_PLANS else None
    return SimRun(
        model=model,
        scenario=scenario,
        seed=int(seed),
        t=_readonly(t),
        axis_names=tuple(model.axes[i].name for i in indices),
        r=r_all,
        u=stack("u", np.float64),
        a=stack("a", np.float64),
        eps=stack("eps", np.float64),
        code=stack("raw0", np.int32) if analog else None,  # calibrated: no raw input beside accel
        t1=stack("raw0", np.int32) if duty else None,
        t2=stack("raw1", np.int32) if duty else None,
        clipped=stack("clipped", bool),
        accel=stack("accel", np.float64),
        initial_random=initial_random,
        stance=None if stance is None else _readonly(np.array(stance)),
        rest=None if rest is None else _readonly(np.array(rest)),
        fixes=None if fixes is None else _readonly(fixes),
    )


def scenario_fixes(
    scenario: str, t: np.ndarray, r: np.ndarray, indices: Sequence[int], ss: np.random.SeedSequence
) -> np.ndarray:
    """Position fixes of ``scenario`` (FIX_PLANS: every ``period`` s from t = 0, standard deviation
    ``sigma``) on the true positions r (N, columns), the columns being model axes ``indices``: (M, 4) rows
    [t, column, r + sigma w, sigma], column by column, w ~ N(0, 1) drawn per fix and model axis from ``ss``
    (so a shorter run's fixes are a prefix of a longer one's, and an axis's fixes do not depend on which
    other axes are simulated)."""
    period, sigma = FIX_PLANS[scenario]
    Ts = float(t[1] - t[0]) if len(t) > 1 else 1.0
    k = np.rint(np.arange(0.0, float(t[-1]) + Ts / 2, period) / Ts).astype(np.int64)
    k = k[k < len(t)]
    w = np.random.default_rng(ss).standard_normal((len(k), MAX_AXES))
    rows = [
        np.column_stack([t[k], np.full(len(k), float(j)), r[k, j] + sigma * w[:, i], np.full(len(k), sigma)])
        for j, i in enumerate(indices)
    ]
    return np.concatenate(rows, axis=0)


def _axis_indices(model: Model, axes: Sequence[str | int] | None) -> list[int]:
    names = [ax.name for ax in model.axes]
    if axes is None:
        return list(range(len(names)))
    accepted = f"a list of axis names {names} or indices 0..{len(names) - 1}"
    if isinstance(axes, (str, int)):
        raise ValueError(f"axes: got {axes!r}; accepted: {accepted}")
    out = []
    for ax in axes:
        if isinstance(ax, str) and ax in names:
            out.append(names.index(ax))
        elif isinstance(ax, (int, np.integer)) and not isinstance(ax, bool) and 0 <= ax < len(names):
            out.append(int(ax))
        else:
            raise ValueError(f"axes: no axis {ax!r}; accepted: {accepted}")
    if not out or len(set(out)) != len(out):
        raise ValueError(f"axes: got {list(axes)!r}; accepted: {accepted}, each at most once")
    return out


# --------------------------------------------------------------------------
# The three stages of one axis. Public so that tests and other tools can
# use them on their own.


def bias(
    model: Model,
    axis: int | str,
    t: np.ndarray,
    rng_walk: np.random.Generator,
    rng_start: np.random.Generator,
    initial_random: bool = True,
) -> np.ndarray:
    """True bias eps [m/s^2] of ``axis`` at the instants t [s] (uniform, from 0, period model.Ts).

    eps = c1 (1 - exp(-t/T)) + c2 + g, g[k+1] = exp(-Ts/T) g[k] + w[k],
    w ~ N(0, Ts sigma_eps^2); g[0] = 0, or N(0, initial_sigma[3]^2) if
    ``initial_random``.
    """
    ax = model.axis(axis)
    n = len(t)
    Ts = model.Ts
    phi = math.exp(-Ts / ax.T)
    drive = np.empty(n)
    drive[0] = model.filter.initial_sigma[3] * rng_start.standard_normal() if initial_random else 0.0
    drive[1:] = math.sqrt(Ts) * model.noise.sigma_eps * rng_walk.standard_normal(n - 1)
    g = signal.lfilter([1.0], [1.0, -phi], drive)  # g[k] = phi g[k-1] + drive[k]
    return ax.c1 * -np.expm1(-t / ax.T) + ax.c2 + g


def noise_sigma_rho(model: Model) -> tuple[float, float]:
    """(sigma [m/s^2], rho): std and lag-1 correlation of the sampled sensor noise."""
    B = model.sensor.bandwidth_hz
    sigma = model.sensor.noise_density_g_rthz * G0 * math.sqrt(math.pi / 2.0 * B)
    return sigma, math.exp(-2.0 * math.pi * B * model.Ts)


def sensor_noise(model: Model, n: int, rng: np.random.Generator) -> np.ndarray:
    """n samples [m/s^2] of the sensor noise: stationary AR(1), see :func:`noise_sigma_rho`."""
    sigma, rho = noise_sigma_rho(model)
    drive = rng.standard_normal(n)
    drive[0] *= sigma
    drive[1:] *= sigma * math.sqrt(1.0 - rho * rho)
    return signal.lfilter([1.0], [1.0, -rho], drive)  # n[k] = rho n[k-1] + drive[k]


def read_out(model: Model, axis: int | str, m: np.ndarray, rng_jitter: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Raw samples for the sensed acceleration m [m/s^2]: (code,) or (t1, t2), int32; (value,) for calibrated.

    A calibrated sensor gives m in its unit, rounded to its LSB when the model
    declares one (int16 counts of a digital part) and saturated at its full scale.
    """
    ax = model.axis(axis)
    if model.sensor.kind == "calibrated":
        c = model.sensor.calibrated
        scale = G0 if c.unit == "g" else 1.0
        full = model.max_accel_m_s2
        v = np.clip(m, -full, full)
        if c.lsb_per_g > 0:
            lsb = G0 / c.lsb_per_g
            v = np.clip(np.rint(v / lsb) * lsb, -full, full)
        return (v / scale,)
    if model.sensor.kind == "analog":
        an = model.sensor.analog
        volts = np.clip(ax.zero_g + ax.sensitivity * m / G0, 0.0, an.supply_v)
        full = 2**an.adc_bits
        code = np.clip(np.rint(volts / an.adc_ref_v * full), 0, full - 1)
        return (code.astype(np.int32),)
    dc = model.sensor.duty_cycle
    duty = np.clip(ax.zero_g + ax.sensitivity * m / G0, 0.0, 1.0)
    v = rng_jitter.random(len(m))
    half = JITTER_FRACTION / 2.0
    t2 = dc.t2_counts + np.where(v < half, -1, np.where(v >= 1.0 - half, 1, 0))
    t1 = np.rint(duty * t2)
    return t1.astype(np.int32), t2.astype(np.int32)
