"""Range analysis and format choice for the fixed-point filter of one axis.

Every variable of the generated C gets a bound derived from the declared
ranges and the design numbers, and from that bound its word and binary point
(:func:`codegen.qformat.fit`). The derivations, one per variable:

* z (acceleration from the raw input): the conversion at its extreme valid
  raw values (ADC codes 1 and full_code - 1; duty 0 and 1).
* a, eps (estimates): linear in z, x0 and b, so |a| <= L_a max|z| + |x0_a| +
  L_ab |b|, where L is the l1 norm of the impulse response of the closed
  (a, eps) loop; computed exactly for the transient gains (the first
  N_TRANSIENT samples, all rows) and for the steady gains at several points
  of the declared run (the tail), then given 25 % margin.
* y = z - a - eps: |z| + |a| + |eps|.
* u and r: the declared max |u| and max |r| with a guard factor 2. The
  filter's u and r integrate without feedback, so no analysis bounds them;
  they saturate and each saturation is counted.
* P block, c = P H', S, K: the float64 Riccati over the declared run
  (data-independent) with a factor 2; predict-only samples make P grow, so
  these saturate and count too (covariance form only).

The error of each state against float64 is bounded the same way: every
rounding is an injection of at most half an LSB; injections into a and eps
are carried by the l1 norms of the closed loop, and u and r add up theirs
(and those of a) without feedback.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .design import AnalogConversion, AxisDesign, DutyConversion, axis_design, input_conversion
from .gains import GainRun, gap_maxima, riccati
from .model import G0, Model, ModelError
from .qformat import QFormat, bits_for, const_format, fit

N_TRANSIENT = 600  # samples whose time-varying gains are analysed row by row
MARGIN = 1.25
GUARD = 2.0
MAX_GAP_S = 0.25  # longest run of skipped samples the covariance ranges cover (no model key yet)


class RangeError(ModelError):
    """A variable that no word of the generated C can hold."""


@dataclass(frozen=True)
class Var:
    name: str
    unit: str
    bound: float
    fmt: QFormat
    note: str = ""
    saturates: bool = False

    @property
    def resolution(self) -> float:
        return self.fmt.lsb


@dataclass(frozen=True)
class L1:
    """l1 gains of the closed (a, eps) loop: from an input-like error (z), from a
    push into a, from a push into eps; to a and to eps."""

    z_a: float
    z_e: float
    a_a: float
    a_e: float
    e_a: float
    e_e: float


@dataclass
class AxisPlan:
    model: Model
    design: AxisDesign
    conv: AnalogConversion | DutyConversion
    form: str
    n_run: int
    gains: GainRun
    l1: L1
    vars: dict[str, Var] = field(default_factory=dict)
    consts: dict[str, tuple[float, QFormat]] = field(default_factory=dict)
    z_error: float = 0.0
    gap: int = 0

    def f(self, name: str) -> int:
        return self.vars[name].fmt.frac


def _require(model: Model, name: str, unit: str, bound: float, word: int, min_frac: int | None = None) -> QFormat:
    """fit() that refuses, naming the variable, its range and the bits it would need."""
    ib = bits_for(bound)
    need = ib + 1 + (min_frac if min_frac is not None else 0)
    if ib > word - 2 or (min_frac is not None and need > word):
        raise RangeError(
            model.source,
            name,
            f"range +-{bound:.6g} {unit} needs {need} bits ({ib} integer + sign"
            + (f" + {min_frac} fraction" if min_frac is not None else "")
            + f"); the widest word is {word} bits",
        )
    return fit(bound, word)


# --------------------------------------------------------------------------
# l1 norms of the closed (a, eps) loop


def _closed(K2: np.ndarray, phi: float) -> np.ndarray:
    """A = (I - K h) F2 for the (a, eps) block, h = [1, 1]."""
    F2 = np.diag([1.0, phi])
    return (np.eye(2) - np.outer(K2, [1.0, 1.0])) @ F2


def _l1_steady(A: np.ndarray, B: np.ndarray, horizon: int) -> np.ndarray:
    """sum_{m>=0} |A^m B| (2x2 result: rows = output a/eps, cols = input), by eigen-decomposition."""
    lam, V = np.linalg.eig(A)
    Vi = np.linalg.inv(V)
    out = np.zeros((2, B.shape[1]))
    if np.iscomplexobj(lam) and np.any(np.abs(lam.imag) > 0):
        raise ValueError("complex closed-loop poles")
    lam = lam.real
    V = V.real
    Vi = Vi.real
    chunk = 1 << 18
    m0 = 0
    while m0 < horizon:
        m = np.arange(m0, min(horizon, m0 + chunk), dtype=np.float64)
        pw = np.power(lam[:, None], m[None, :])
        # h[m] = V diag(lam^m) Vi B
        for o in range(2):
            for i in range(B.shape[1]):
                coef = V[o, :] * (Vi @ B[:, i])
                out[o, i] += np.abs(coef @ pw).sum()
        m0 += chunk
        if np.max(np.abs(lam)) ** m0 < 1e-13:
            break
    return out


def l1_gains(d: AxisDesign, g: GainRun) -> L1:
    phi = d.phi
    n = len(g.K)
    K2 = g.K[:, 2:4]
    # transient: every output row k < N_TRANSIENT, exactly; Phi(k, j) for all j kept as a stack
    nt = min(N_TRANSIENT, n)
    best = np.zeros((2, 3))
    stack = np.zeros((0, 2, 2))
    inputs = np.zeros((0, 2, 3))
    for k in range(nt):
        A = _closed(K2[k], phi) if k else np.eye(2)
        stack = A @ stack if len(stack) else stack
        # injections at sample k: z-like (enters through K), into a, into eps (after the update)
        B = np.column_stack([K2[k], [1.0, 0.0], [0.0, 1.0]])
        stack = np.concatenate([stack, np.eye(2)[None]], axis=0)
        inputs = np.concatenate([inputs, B[None]], axis=0)
        rows = np.abs(stack @ inputs).sum(axis=0)  # (2, 3)
        best = np.maximum(best, rows)
    # tail: steady gains at several points; a tail row also carries what the transient left
    horizon = int(40.0 / max(1e-12, 1.0 - phi)) + 100_000
    for k in sorted({min(n - 1, x) for x in (nt, 10 * nt, n // 10, n // 3, n - 1)}):
        A = _closed(K2[k], phi)
        B = np.column_stack([K2[k], [1.0, 0.0], [0.0, 1.0]])
        best = np.maximum(best, _l1_steady(A, B, horizon) + rows)
    best *= MARGIN
    return L1(best[0, 0], best[1, 0], best[0, 1], best[1, 1], best[0, 2], best[1, 2])


# --------------------------------------------------------------------------


def z_bound(conv) -> float:
    if isinstance(conv, AnalogConversion):
        ends = conv.accel(np.array([1, conv.full_code - 1]))
        return float(np.max(np.abs(ends)))
    lo = (0.0 - conv.zero_g_duty) / conv.duty_per_g * G0
    hi = (1.0 - conv.zero_g_duty) / conv.duty_per_g * G0
    return max(abs(lo), abs(hi))


def plan_axis(model: Model, axis: int | str, form: str | None = None) -> AxisPlan:
    form = form or model.filter.form
    d = axis_design(model, axis)
    conv = input_conversion(model, axis)
    n_run = int(math.ceil(model.ranges.max_run_s * model.rate_hz))
    if n_run > 2**31 - 1:
        raise RangeError(model.source, "ranges.max_run_s", f"{n_run} samples do not fit the 31-bit sample counter")
    g = riccati(d, n_run)
    l1 = l1_gains(d, g)
    p = AxisPlan(model, d, conv, form, n_run, g, l1)
    Ts = d.Ts
    sig0 = np.sqrt(np.diag(d.P0))

    zb = z_bound(conv)
    a_b = l1.z_a * zb + abs(d.x0[2]) + 6 * sig0[2]
    e_b = l1.z_e * zb + abs(d.x0[3]) + abs(d.eps_mean) + 6 * sig0[3]
    y_b = zb + a_b + e_b
    fy = _require(model, "y", "m/s^2", y_b, 32)
    add = p.vars.__setitem__
    add("z", Var("z", "m/s^2", zb, fy, "input acceleration; shares the format of y"))
    add("y", Var("y", "m/s^2", y_b, fy, "innovation z - a - eps"))
    add("a", Var("a", "m/s^2", a_b, fy, f"l1 gain z->a {l1.z_a:.3g} x max|z|, shares the format of y"))
    add("e", Var("e", "m/s^2", e_b, _require(model, "eps", "m/s^2", e_b, 64), f"l1 gain z->eps {l1.z_e:.3g}"))
    vb = GUARD * Ts * model.ranges.max_velocity_m_s
    add("v", Var("v", "m", vb, _require(model, "ranges.max_velocity_m_s", "m", vb, 64), "Ts*u, 2x max|u|", True))
    rb = GUARD * model.ranges.max_position_m
    add("r", Var("r", "m", rb, _require(model, "ranges.max_position_m", "m", rb, 64), "2x max|r|", True))
    ub = GUARD * model.ranges.max_velocity_m_s
    add("u_out", Var("u_out", "m/s", ub, _require(model, "ranges.max_velocity_m_s", "m/s", ub, 64), "read-out of u"))

    # constants of the predict step, each with its own scaling
    def const(name, value, word=32):
        if value == 0:
            p.consts[name] = (0.0, QFormat(word, word - 2))
        else:
            p.consts[name] = (value, const_format(value, word))

    const("H2", Ts * Ts / 2.0)
    const("T2", Ts * Ts)
    const("OMP", 1.0 - d.phi)
    const("RATE", 1.0 / Ts)
    p.consts["B"] = (float(d.b[3]), p.vars["e"].fmt)
    for nm in ("H2", "T2", "RATE"):
        fr = p.consts[nm][1].frac
        if fr + fy.frac - p.f("v") < -62 or fr < 0 and nm != "RATE":
            raise RangeError(model.source, "sampling.rate_hz", f"{nm} = {p.consts[nm][0]:.6g} cannot be scaled")

    _plan_input(p)
    if form == "covariance":
        _plan_covariance(p)
    else:
        _plan_gain_formats(p)
    return p


def _plan_input(p: AxisPlan) -> None:
    conv = p.conv
    fz = p.f("z")
    if isinstance(conv, AnalogConversion):
        cs = const_format(conv.scale)
        p.consts["SCALE"] = (conv.scale, cs)
        p.consts["OFFSET"] = (conv.offset, QFormat(64, cs.frac))
        if cs.frac - fz < 1:
            raise RangeError(p.model.source, "sensor.analog", f"the code scale {conv.scale:.6g} m/s^2 cannot be scaled")
        # |code| dSCALE + dOFFSET + half an LSB of z
        p.z_error = conv.full_code * cs.lsb / 2 + cs.lsb / 2 + 2.0**-fz / 2
    else:
        if conv.t2_nominal * 1.25 >= 2**30:
            raise RangeError(
                p.model.source,
                "sensor.duty_cycle.t2_period_s",
                f"T2 up to {conv.t2_nominal * 1.25:.6g} counts needs 31 bits; accepted: below 2**30 counts",
            )
        gain = G0 / conv.duty_per_g
        cg = const_format(gain)
        p.consts["DGAIN"] = (gain, cg)
        p.consts["DZERO"] = (conv.zero_g_duty * gain, QFormat(64, 31 + cg.frac))
        if 31 + cg.frac - fz < 1:
            raise RangeError(p.model.source, "sensor.duty_cycle", f"the duty gain {gain:.6g} cannot be scaled")
        # reciprocal (relative 2**-27) and duty rounding, gain and zero rounding, z rounding
        p.z_error = (2.0**-27 + 2.0**-31) * gain + cg.lsb / 2 + 2.0 ** -(31 + cg.frac) + 2.0**-fz / 2


def _gain_bounds(p: AxisPlan) -> np.ndarray:
    """|K| bounds in the C's coordinates [r, v = Ts u, a, eps]."""
    kmax = np.abs(p.gains.K).max(axis=0) * np.array([1.0, p.design.Ts, 1.0, 1.0])
    return kmax


def _plan_gain_formats(p: AxisPlan) -> None:
    kb = _gain_bounds(p)
    for i, nm in enumerate(("Kr", "Kv", "Ka", "Ke")):
        p.vars[nm] = Var(nm, "1", kb[i], const_format(kb[i]), "gain, per-constant scaling")


BLOCK = ("ra", "va", "aa", "re", "ve", "ae", "ee")


def _plan_covariance(p: AxisPlan) -> None:
    """The block is carried as (c_r, P_re, c_v, P_ve, P_aa, P_ae, P_ee), c = P H'.

    P_ra and P_re grow with the run (P_ra ~ 34 m^2/s^2 after 20 min) while their
    sum c_r, which is all the gain needs, stays ~1e-3: carrying c_r in its own
    fine format instead of P_ra removes the cancellation (likewise c_v for v).
    """
    g = p.gains
    Ts = p.design.Ts
    gap = max(1, int(round(MAX_GAP_S * p.model.rate_hz)))
    gg = gap_maxima(p.design, g, gap, 4 * gap + 50)
    pm = np.maximum(np.maximum(g.max_prior, g.max_post), np.maximum(gg.max_prior, gg.max_post))
    mc = np.maximum(g.max_c, gg.max_c)
    p.gap = gap
    bounds = {
        "cr": mc[0],
        "Pre": pm[3],
        "cv": Ts * mc[1],
        "Pve": Ts * pm[4],
        "ca": max(mc[2], float(g.S.max()), float(gg.S.max())),
        "Pae": pm[5],
        "ce": mc[3],
    }
    notes = {
        "cr": "c_r = P_ra + P_re",
        "Pre": "P_re",
        "cv": "c_v = Ts (P_ua + P_ue)",
        "Pve": "Ts P_ue",
        "ca": "c_a = P_aa + P_ae (and S)",
        "Pae": "P_ae",
        "ce": "c_e = P_ae + P_ee",
    }
    fmts = {}
    for nm, b in bounds.items():
        fmts[nm] = _require(p.model, f"covariance {notes[nm]}", "(SI units squared)", GUARD * b, 32)
        p.vars[nm] = Var(nm, "cov", GUARD * b, fmts[nm], notes[nm] + ", Riccati max x2", True)
    p.vars["S"] = Var("S", "(m/s^2)^2", GUARD * bounds["ca"], fmts["ca"], "H P H' + R, >= R", True)
    kb = np.maximum(np.abs(g.K).max(0), gg.K[0]) * np.array([1.0, Ts, 1.0, 1.0])
    for i, nm in enumerate(("Kr", "Kv", "Ka", "Ke")):
        p.vars[nm] = Var(nm, "1", GUARD * kb[i], const_format(GUARD * kb[i]), "K = c / S, Riccati max x2", True)
    d = p.design
    fa = fmts["ca"]
    p.consts["PHI"] = (d.phi, QFormat(32, 31))
    p.consts["PHI2"] = (d.phi**2, QFormat(32, 31))
    p.consts["PHIOMP"] = (d.phi * (1 - d.phi), const_format(d.phi * (1 - d.phi)))
    p.consts["R"] = (d.R, fa)
    p.consts.update(
        {
            "Qra": (d.Q[0, 2], fmts["cr"]),
            "Qva": (Ts * d.Q[1, 2], fmts["cv"]),
            "Qaa": (d.Q[2, 2], fa),
            "Qee": (d.Q[3, 3], fmts["ce"]),
        }
    )
    R_int = round(d.R * 2**fa.frac)
    if R_int < 2**12:
        raise RangeError(
            p.model.source,
            "noise.R",
            f"R = {d.R:.6g} is {R_int} LSB of the covariance format {fa}; needs at least 13 bits below the "
            f"largest covariance {bounds['ca']:.6g}",
        )
