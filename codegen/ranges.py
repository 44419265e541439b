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
* y = z - a - eps: |z| + |a| + |eps|. z, y and a share one int32 format.
* eps: int64 in Q.(fy + 32), so its high word is in the format of y: the
  innovation reads eps by one rounding of the high word, and K_e y (K_e in
  Q.32 when it fits) and the decay (1 - phi)(eps_hi - eps_bar) (1 - phi in
  Q.32 when that keeps 13 bits) each add into it with one SMLAL, no shift.
  32 bits below y's LSB: the bias mode's l1 gain (~T/Ts) multiplies the
  per-step rounding of eps, so eps needs far more resolution than a.
* u and r: the declared max |u| and max |r| with a guard factor 2. The
  filter's u and r integrate without feedback, so no analysis bounds them;
  they are clamped once per step (on their high words) and each clamp is
  counted. r is int64 in a format holding 2 max|r| plus one step; v = Ts u
  is int64 in the format of the products K_v y and Ts^2 a when that holds
  2 Ts max|u| plus one step, so they accumulate into it without a shift.
  K_r and K_v share their formats with Ts^2/2 and Ts^2 (when that leaves
  Ts^2/2 at least 20 bits): r += v + (Ts^2/2 a + K_r y) needs one shift.
* P block, c = P H', S, K: the float64 Riccati over the declared run
  (data-independent) with a factor 2; predict-only samples make P grow, so
  these saturate and count too (covariance form only).

The error of each state against float64: :mod:`codegen.bounds`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from accelnav.model.design import AnalogConversion, AxisDesign, DutyConversion, axis_design, input_conversion
from accelnav.model.load import G0, Model, ModelError

from .gains import KEEP, GainRun, gap_maxima, riccati
from .qformat import QFormat, bits_for, const_format, fit

N_TRANSIENT = 600  # samples whose time-varying gains are analysed row by row
MARGIN = 1.25
GUARD = 2.0
MAX_GAP_S = 0.25  # longest run of skipped samples the covariance ranges cover (no model key yet)


class RangeError(ModelError):
    """A variable that no word of the generated C can hold."""


def refuse_calibrated(model: Model) -> None:
    """The generated C (fixed point or float32) starts from the MCU's raw input; a calibrated sensor has
    none to describe."""
    if model.sensor.kind == "calibrated":
        raise RangeError(
            model.source,
            "sensor.kind",
            "'calibrated' data (already in g or m/s^2) are for the host tools; the generated C reads an ADC or a "
            "timer capture: accepted for codegen, hil and firmware: 'analog' or 'duty_cycle'",
        )


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
    step_max: float = 0.0
    kv_room: float = 0.0
    sat_free: frozenset = frozenset()  # predict sums that fit int32 for every int32 input (no clamp)
    v_step: float = 0.0  # largest |v| increment of one step
    conv_shift: int = -1  # analog fast path: code << conv_shift (-1: the int64 path)
    gap_run: GainRun | None = None  # gain schedule: maxima over gaps of `gap` samples (codegen.follow)
    theta: dict = field(default_factory=dict)  # covariance: c_r, c_v, c_a, c_e levels of the switch to fine

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


# terms of the l1 sum added one by one when the poles allow no closed form; the rest of the horizon
# gets a closed-form upper bound, so the work is bounded whatever the horizon (issue 21 item 6: a horizon
# of 40/(1 - phi) with phi rounded to 1.0 ran for hours)
L1_EXACT_TERMS = 1 << 20


def _l1_steady(A: np.ndarray, B: np.ndarray, horizon: int) -> np.ndarray:
    """sum_{m<horizon} |A^m B| (2x2 result: rows = output a/eps, cols = input), by eigen-decomposition:
    exact in closed form for two distinct poles in (0, 1); otherwise exact over the first
    L1_EXACT_TERMS terms and bounded above past them (never below the true sum)."""
    lam, V = np.linalg.eig(A)
    Vi = np.linalg.inv(V)
    out = np.zeros((2, B.shape[1]))
    if np.iscomplexobj(lam) and np.any(np.abs(lam.imag) > 0):
        raise ValueError("complex closed-loop poles")
    lam = lam.real
    V = V.real
    Vi = Vi.real
    if np.all(lam > 0) and np.all(lam < 1) and lam[0] != lam[1]:
        return _l1_two_geometric(lam, V, Vi, B, horizon)
    chunk = 1 << 18
    exact = min(horizon, L1_EXACT_TERMS)
    m0 = 0
    while m0 < exact:
        m = np.arange(m0, min(exact, m0 + chunk), dtype=np.float64)
        pw = np.power(lam[:, None], m[None, :])
        # h[m] = V diag(lam^m) Vi B
        for o in range(2):
            for i in range(B.shape[1]):
                coef = V[o, :] * (Vi @ B[:, i])
                out[o, i] += np.abs(coef @ pw).sum()
        m0 = min(exact, m0 + chunk)
        if np.max(np.abs(lam)) ** m0 < 1e-13:  # what is left is below rounding: no tail
            return out
    if exact < horizon:  # |c0 lam0^m + c1 lam1^m| <= |c0| |lam0|^m + |c1| |lam1|^m, summed in closed form
        tail = [_geo_abs(abs(float(x)), exact, horizon - 1) for x in lam]
        for o in range(2):
            for i in range(B.shape[1]):
                coef = V[o, :] * (Vi @ B[:, i])
                out[o, i] += float(np.abs(coef) @ tail)
    return out


def _geo_abs(lm: float, a: int, b: int) -> float:
    """sum_{m=a}^{b} lm^m for lm >= 0 (inf when it overflows)."""
    n = b - a + 1
    if n <= 0:
        return 0.0
    if lm == 1.0:
        return float(n)
    with np.errstate(over="ignore", divide="ignore"):
        if lm < 1.0:
            return float(np.float64(lm) ** a * -math.expm1(n * math.log(lm)) / (1.0 - lm)) if lm > 0 else 0.0
        return float(np.float64(lm) ** a * np.expm1(n * np.log(lm)) / (lm - 1.0))


def _l1_two_geometric(lam, V, Vi, B, horizon: int) -> np.ndarray:
    """sum_{m<horizon} |c0 lam0^m + c1 lam1^m| in closed form, for 0 < lam < 1: the sum changes sign
    at most once (at (lam0/lam1)^m = -c1/c0), and on each side it is two geometric series."""

    def geo(lm: float, a: int, b: int) -> float:  # sum_{m=a}^{b} lm^m
        if b < a:
            return 0.0
        return lm**a * -math.expm1((b - a + 1) * math.log(lm)) / (1.0 - lm)

    out = np.zeros((2, B.shape[1]))
    for o in range(2):
        for i in range(B.shape[1]):
            c = V[o, :] * (Vi @ B[:, i])
            cuts = [0, horizon]
            if c[0] != 0 and c[1] != 0 and -c[1] / c[0] > 0:
                ms = math.log(-c[1] / c[0]) / math.log(lam[0] / lam[1])
                if 0 <= ms < horizon - 1:
                    cuts = [0, int(math.floor(ms)) + 1, horizon]
            for a, b in zip(cuts[:-1], cuts[1:], strict=False):
                out[o, i] += abs(c[0] * geo(lam[0], a, b - 1) + c[1] * geo(lam[1], a, b - 1))
    return out


def l1_rows(n: int) -> list[int]:
    """The samples whose steady gains l1_gains takes for the tail."""
    nt = min(N_TRANSIENT, n)
    return sorted({min(n - 1, x) for x in (nt, 10 * nt, n // 10, n // 3, n - 1)})


def l1_gains(d: AxisDesign, g: GainRun) -> L1:
    phi = d.phi
    n = g.n
    K2 = g.K[:, 2:4]  # the first N_TRANSIENT rows are always kept
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
    for k in l1_rows(n):
        K2k = g.at(k)[0][2:4]
        A = _closed(K2k, phi)
        B = np.column_stack([K2k, [1.0, 0.0], [0.0, 1.0]])
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


# rate_hz x max_run_s per axis the generator accepts: its time is linear in it (~1.5 s for 3 axes at the
# limit on the 2-core build machine, bench/speed/bench_codegen_cost.py), its memory is not; and below the C's
# 31-bit sample counter
MAX_RUN_SAMPLES = 2**23
assert MAX_RUN_SAMPLES < 2**31


def run_samples(model: Model) -> int:
    """Samples of the declared run, refused in one line when the generator would take too long: the
    Riccati and the bound recursions cost a constant time per sample (memory does not grow with it)."""
    n_run = int(math.ceil(model.ranges.max_run_s * model.rate_hz))
    if n_run > MAX_RUN_SAMPLES:
        lim = MAX_RUN_SAMPLES
        raise RangeError(
            model.source,
            "sampling.rate_hz x ranges.max_run_s",
            f"{model.rate_hz:g} Hz x {model.ranges.max_run_s:g} s = {n_run:.4g} samples per axis is too long a run "
            f"to generate for; accepted: at most {lim} (2**23), e.g. {lim / 1e3 / 3600:.2f} h at 1 kHz, "
            f"{lim / 1e4 / 60:.0f} min at 10 kHz, {lim / 1e5:.0f} s at 100 kHz",
        )
    return n_run


def plan_axis(model: Model, axis: int | str, form: str | None = None) -> AxisPlan:
    form = form or model.filter.form
    refuse_calibrated(model)
    d = axis_design(model, axis)
    conv = input_conversion(model, axis)
    n_run = run_samples(model)
    g = riccati(d, n_run, keep=min(n_run, KEEP), rows=(*l1_rows(n_run), min(int(model.rate_hz), n_run - 1)))
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
    # eps: 64 bits whose high word is in the format of y (the innovation reads it by one rounding of the
    # high word, and K_e y adds into it without a shift); e_b <= y_b, so it fits
    add(
        "e", Var("e", "m/s^2", e_b, QFormat(64, fy.frac + 32), f"l1 gain z->eps {l1.z_e:.3g}; high word in Q.{fy.frac}")
    )
    # r and v = Ts u share one 64-bit format, so r += v is a plain add; they saturate (clamped once per
    # step, on the high word, counted): nothing feeds them back, so no analysis bounds them
    vb = GUARD * Ts * model.ranges.max_velocity_m_s
    rb = GUARD * model.ranges.max_position_m
    _require(model, "ranges.max_velocity_m_s", "m", vb, 64)
    _require(model, "ranges.max_position_m", "m", rb, 64)
    kb = _schedule_gain_bounds(p) if form == "gain_schedule" else None
    p.step_max = vb + Ts * Ts * a_b + (GUARD * 0.25 + 1) * y_b  # |K_r|, |K_v| < 0.25 (checked below)
    fr = _require(model, "ranges.max_position_m", "m", rb + p.step_max, 64)
    # v gets the format of the products K_v y and Ts^2 a, so they accumulate into it with no shift
    # (one SMLAL each), when that format holds v and one step's increment
    kv_b = 2 * GUARD * float(g.kmax[1]) * Ts  # K_v (Ts u gain) bound, with room for skips
    p.kv_room = kv_b
    if kb is not None:  # gain schedule: the gains after a gap (codegen.follow) reach kb
        kv_b = max(kv_b, float(kb[1]))
    v_step = Ts * Ts * a_b + kv_b * y_b
    p.v_step = v_step
    fv = _require(model, "ranges.max_velocity_m_s", "m", vb + v_step, 64)
    if kb is not None:  # gain schedule: v in the format of K_v y, K_v's format wide enough for its gaps
        fv = QFormat(64, min(fv.frac, const_format(max(float(kb[1]), Ts * Ts)).frac + fy.frac))
    add("v", Var("v", "m", vb, fv, "Ts*u, 2x max|u|", True))
    add("r", Var("r", "m", rb, fr, "2x max|r|", True))
    ub = GUARD * model.ranges.max_velocity_m_s
    add("u_out", Var("u_out", "m/s", ub, _require(model, "ranges.max_velocity_m_s", "m/s", ub, 64), "read-out of u"))

    # constants of the predict step, each with its own scaling
    def const(name, value, word=32):
        if value == 0:
            p.consts[name] = (0.0, QFormat(word, word - 2))
        else:
            p.consts[name] = (value, const_format(value, word))

    # 1 - phi in Q.32 when that keeps 13 bits: eps -= (1 - phi)(eps_hi - eps_bar) is then one SMLAL
    omp = 1.0 - d.phi
    p.consts["OMP"] = (omp, QFormat(32, 32) if omp * 2**32 >= 2**13 else const_format(omp))
    const("RATE", 1.0 / Ts)
    # eps' = phi eps + b = eps - (1 - phi)(eps - eps_bar), eps_bar = b / (1 - phi) = c1 + c2
    p.consts["EBAR"] = (float(d.b[3] / (1.0 - d.phi)), fy)
    if p.consts["OMP"][1].frac - 32 < 0:
        raise RangeError(model.source, f"axes.{d.axis.name}.T", f"1 - phi = {1 - d.phi:.6g} cannot be scaled")
    _plan_input(p)
    if form == "covariance":
        _plan_covariance(p)
    else:
        _plan_gain_formats(p, kb)
        _plan_schedule_follow(p)
    # Ts^2/2 shares the format of K_r, Ts^2 that of K_v: r += v + (Ts^2/2 a + K_r y) needs one shift
    # (when that leaves Ts^2/2 fewer than 20 bits, it gets its own format and a second shift)
    # (gain schedule: 18 bits, its K_r format being wide enough for the gains after a gap; there
    # Ts^2/2 too small for K_r's format takes v's product format Q.(fv - fy) when v is in K_v's and it
    # keeps 18 bits there: Ts^2/2 a accumulates onto v before v is shifted into r's increment, one
    # SMLAL and no shift of its own, codegen.emit_c._core_fixed)
    min_bits = 18 if form == "gain_schedule" else 20
    fva = p.vars["v"].fmt.frac - fy.frac
    gs_v = form == "gain_schedule" and p.vars["Kv"].fmt.frac == fva and fva >= p.vars["Kr"].fmt.frac
    for nm, kn, val in (("H2", "Kr", Ts * Ts / 2.0), ("T2", "Kv", Ts * Ts)):
        f = p.vars[kn].fmt
        if val * 2**f.frac < 2**min_bits:
            on_v = nm == "H2" and gs_v and 2**min_bits <= val * 2**fva < 2**31
            f = QFormat(32, fva) if on_v else const_format(val)
        p.consts[nm] = (val, f)
        for fm in (f, p.vars[kn].fmt):
            if fm.frac + fy.frac - fr.frac < 1:
                raise RangeError(model.source, "sampling.rate_hz", f"{nm} = {val:.6g} cannot be scaled")
    return p


def _plan_input(p: AxisPlan) -> None:
    conv = p.conv
    fz = p.f("z")
    if isinstance(conv, AnalogConversion):
        # unsigned fast path: z = hi((code << c) x SCALE) + OFFSET, SCALE a 32-bit unsigned mantissa
        fs = 31 - bits_for(conv.scale) + 1  # conv.scale 2^fs in [2^31, 2^32)
        c = fz + 32 - fs
        if c >= 0 and conv.full_code * 2**c < 2**32 and conv.full_code * conv.scale * 2**fz < 2**31:
            p.consts["SCALE"] = (conv.scale, QFormat(33, fs))
            # + half an LSB turns the floor of the high word into round to nearest
            p.consts["OFFSET"] = (conv.offset + 2.0 ** -(fz + 1), QFormat(32, fz))
            p.conv_shift = c
            p.z_error = conv.full_code * 2.0 ** -(fs + 1) + 2.0**-fz
            return
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


def _schedule_gain_bounds(p: AxisPlan) -> np.ndarray:
    """Gain-schedule form: |K| bounds in the C's coordinates [r, v = Ts u, a, eps], wide enough for the
    gains that follow a gap of up to MAX_GAP_S (codegen.follow carries the deviation from the schedule
    there; beyond, it clamps a gain to its format and the stated bound takes the clamped gain), with
    the margin of the l1 gains. Sets p.gap and p.gap_run (the block's maxima over those gaps)."""
    g = p.gains
    p.gap = max(1, int(round(MAX_GAP_S * p.model.rate_hz)))
    p.gap_run = gap_maxima(p.design, g, p.gap, 4 * p.gap + 50)
    return MARGIN * np.maximum(g.kmax, p.gap_run.kmax) * np.array([1.0, p.design.Ts, 1.0, 1.0])


def _gain_format(p: AxisPlan, nm: str, bound: float, note: str, saturates: bool) -> None:
    """K_r and K_v share their format with Ts^2/2 and Ts^2 (the smaller of the two fits)."""
    Ts = p.design.Ts
    partner = {"Kr": Ts * Ts / 2.0, "Kv": Ts * Ts}.get(nm, 0.0)
    fmt = const_format(max(bound, partner))
    if nm == "Ke" and fmt.frac > 32:  # Q.32: K_e y lands in the format of eps (high word = y's)
        fmt = QFormat(32, 32)
    if nm == "Kv":  # the product K_v y in the format of v when it keeps 20 bits of Ts^2
        f = p.vars["v"].fmt.frac - p.vars["y"].fmt.frac
        if f <= fmt.frac and partner * 2**f >= 2**20 and bound <= p.kv_room:
            fmt = QFormat(32, f)
    p.vars[nm] = Var(nm, "1", bound, fmt, note, saturates)


def _plan_gain_formats(p: AxisPlan, kb) -> None:
    for i, nm in enumerate(("Kr", "Kv", "Ka", "Ke")):
        _gain_format(p, nm, kb[i], "gain, per-constant scaling", False)


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
        "ca": max(mc[2], g.S_max, gg.S_max),
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
    kb = np.maximum(g.kmax, gg.kmax) * np.array([1.0, Ts, 1.0, 1.0])
    for i, nm in enumerate(("Kr", "Kv", "Ka", "Ke")):
        _gain_format(p, nm, GUARD * kb[i], "K = c / S, Riccati max x2", True)
    d = p.design
    fa = fmts["ca"]
    p.consts["PHI"] = (d.phi, QFormat(32, 31))
    p.consts["PHI2"] = (d.phi**2, QFormat(32, 31))
    p.consts["PHIOMP"] = (d.phi * (1 - d.phi), const_format(d.phi * (1 - d.phi)))
    p.consts["OMPC"] = (1 - d.phi, const_format(1 - d.phi))
    p.consts["OMP2"] = ((1 - d.phi) * (1 + d.phi), const_format((1 - d.phi) * (1 + d.phi)))
    p.consts["R"] = (d.R, fa)
    p.consts.update(
        {
            "Qra": (d.Q[0, 2], const_format(d.Q[0, 2])),
            "Qva": (Ts * d.Q[1, 2], const_format(Ts * d.Q[1, 2])),
            "Qaa": (d.Q[2, 2], const_format(d.Q[2, 2])),
            "Qee": (d.Q[3, 3], const_format(d.Q[3, 3])),
        }
    )
    p.sat_free = _predict_sat_free(p)
    R_int = round(d.R * 2**fa.frac)
    if R_int < 2**12:
        raise RangeError(
            p.model.source,
            "noise.R",
            f"R = {d.R:.6g} is {R_int} LSB of the covariance format {fa}; needs at least 13 bits below the "
            f"largest covariance {bounds['ca']:.6g}",
        )
    # w = y / S: the innovation divided once by S; each state then adds c_i w = K_i y, so no gain is
    # rounded on its own (only K_e is formed, for the update of P_re, P_ve, P_ae). S >= R and y stays
    # within its analysed bound, so |w| <= max|y| / R and w needs no saturation.
    wb = p.vars["y"].bound / d.R
    if bits_for(wb) > 30:
        raise RangeError(
            p.model.source,
            "noise.R",
            f"R = {d.R:.6g} is too small for the innovation range +-{p.vars['y'].bound:.6g} m/s^2: y / R needs "
            f"{bits_for(wb) + 1} bits; accepted: R >= {p.vars['y'].bound / 2**30:.3g}",
        )
    p.vars["w"] = Var("w", "s^2/m", wb, fit(wb, 32), "y / S, at most max|y| / R")
    _plan_fine(p, g, gap)


FINE = ("cr", "cv", "ca", "ce")  # the carried entries with a second, finer format (and S with c_a)


def _plan_fine(p: AxisPlan, g: GainRun, gap: int) -> None:
    """Fine formats of c_r, c_v, c_a and c_e (and S, which shares c_a's) for the samples away from gaps.

    The formats above hold the block during and after a gap of up to MAX_GAP_S, where c_r, c_v and
    c_a reach 10 to 2000 times what they are in an uninterrupted run; in those formats their steady
    values keep only 11 to 23 significant bits, and that rounding is what the 1 kHz filter departs
    from the float64 filter by. So the C carries them in one of two formats, chosen per step by bit 0
    of the sample counter: the coarse formats above from a skipped sample on, the fine ones below
    once the block is back (codegen.emit_c._core_cov). The switch to fine is made after an update
    whose posterior |c_i| are all within their levels theta_i. Each fine format holds GUARD times the
    largest |c_i| (and |S| for c_a) of the uninterrupted run and of every gap trajectory (gap lengths
    1, 16, 256, ... and MAX_GAP_S, from each checkpoint of the run, 4 gap + 50 updated samples after
    it) from the sample where that switch is made on. theta_i starts at the uninterrupted run's
    largest |c_i|, which sets the formats; then each level is raised as far as those formats still
    hold that condition (the earlier the switch after a gap, the fewer samples the coarse formats
    round), halved back where a trajectory would break it. A skipped sample moves the block to the
    coarse formats before its predict.

    c_e's coarse format is set by its prior P0 (P_ae + P_ee at sample 0, 1e5 times its steady value
    at 1 kHz, where it kept ~12 bits and held eps at 2e-4 sigma on stress data): the uninterrupted run
    from P0 is one more trajectory (:func:`_start_run`), so it starts coarse and switches once c_e has
    come down to theta_e, which starts at the largest |c_e| of the run after its first 1024 samples.
    """
    from .gains import _key

    d, R = p.design, p.design.R
    ck = (_key(d), p.n_run, gap, tuple(p.f(n) for n in ("cr", "cv", "ca", "ce", "Pre", "Pve", "Pae")))
    hit = _FINE.get(ck)  # emit and the report plan the same axis: the analysis once (a local: thread safe)
    if hit is None:
        hit = _fine_levels(p, g, gap)
        if len(_FINE) > 64:
            _FINE.clear()
        _FINE[ck] = hit
    fracs, theta, top = hit
    for nm in FINE:
        c = p.vars[nm]
        i = FINE.index(nm)
        b = max(top[i], top[4]) if nm == "ca" else top[i]
        f = QFormat(32, fracs[nm])
        p.vars[nm + "_f"] = Var(nm + "_f", "cov", GUARD * b, f, c.note.split(",")[0] + ", away from gaps, x2", True)
        p.theta[nm] = float(theta[i])
    p.vars["S_f"] = Var("S_f", "(m/s^2)^2", GUARD * top[4], p.vars["ca_f"].fmt, "S away from gaps", True)
    p.consts["RF"] = (R, p.vars["S_f"].fmt)


_FINE: dict = {}


def _gap_trajectories(d: AxisDesign, P0: np.ndarray, gap: int, recover: int) -> np.ndarray:
    """The float64 Riccati of the seven-entry block (as codegen.gains) from each prior P0[i] (ncp, 4, 4):
    sample 0 is P0 itself, samples below ``gap`` predict only, the ``recover`` after them predict and
    update. Returns the prior c = P H' and S of the updated samples, (recover, ncp, 5: c_r, c_u, c_a, c_e,
    S), every trajectory at once."""
    Ts, phi, R = d.Ts, d.phi, d.R
    h2 = Ts * Ts / 2.0
    # rows: P_ra, P_ua, P_aa, P_re, P_ue, P_ae, P_ee; P = F P F' + Q on them is X -> A X + q
    A = np.zeros((7, 7))
    A[0, :3] = (1.0, Ts, h2)
    A[1, 1:3] = (1.0, Ts)
    A[2, 2] = 1.0
    A[3, 3:6] = (phi, phi * Ts, phi * h2)
    A[4, 4:6] = (phi, phi * Ts)
    A[5, 5] = phi
    A[6, 6] = phi * phi
    q = np.array([d.Q[0, 2], d.Q[1, 2], d.Q[2, 2], 0.0, 0.0, 0.0, d.Q[3, 3]])[:, None]
    Hc = np.array(  # c = P H' = (P_ra + P_re, P_ua + P_ue, P_aa + P_ae, P_ae + P_ee)
        [[1, 0, 0, 1, 0, 0, 0], [0, 1, 0, 0, 1, 0, 0], [0, 0, 1, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1, 1]], dtype=float
    )
    X = np.stack([P0[:, 0, 2], P0[:, 1, 2], P0[:, 2, 2], P0[:, 0, 3], P0[:, 1, 3], P0[:, 2, 3], P0[:, 3, 3]])
    out = np.empty((recover, len(P0), 5))
    for k in range(gap + recover):
        if k:
            X = A @ X + q
        if k >= gap:
            c = Hc @ X
            S = c[2] + c[3] + R
            o = out[k - gap]
            o[:, :4] = c.T
            o[:, 4] = S
            K = c / S  # P = P - K c': the (r, u, a) rows by c_a, the eps column by c_e
            X[:3] -= K[:3] * c[2]
            X[3:] -= K * c[3]
    return out


def _start_run(d: AxisDesign, n_run: int, m: int):
    """The uninterrupted run from its prior P0 as one more trajectory for :func:`_fine_levels`: its first
    m updated samples (prior c and S, (m, 1, 5) as :func:`_gap_trajectories`), and the largest |c| and S
    of the samples after them ((5,); zero when the run has no more), from the Riccati started at the
    prior of sample m (the filter is time invariant: the same samples)."""
    import dataclasses

    from .gains import riccati

    m = min(m, n_run)
    head = _gap_trajectories(d, d.P0[None], 0, m)
    tail = np.zeros(5)
    if n_run > m:
        P, H = d.P0.copy(), d.H[0]
        for k in range(m + 1):  # the prior of sample m
            if k:
                P = d.F @ P @ d.F.T + d.Q
            if k < m:
                c = P @ H
                P = P - np.outer(c, c) / (c[2] + c[3] + d.R)
        g = riccati(dataclasses.replace(d, P0=P), n_run - m, keep=1)  # its maxima only: O(1) memory
        tail = np.r_[np.asarray(g.max_c, dtype=float), g.S_max]
    return head, tail


def _fine_levels(p: AxisPlan, g: GainRun, gap: int):
    """(fine fracs of c_r, c_v, c_a, c_e; switch levels theta (4,); largest |c_r|, |c_v|, |c_a|, |c_e|, S
    (5,) in the fine samples) for :func:`_plan_fine`."""
    d, Ts, R = p.design, p.design.Ts, p.design.R
    cs = np.array([1.0, Ts, 1.0, 1.0])  # C coordinates: c_v = Ts (P_ua + P_ue)
    # the uninterrupted run switches to fine once c_e, whose prior P0 sets its coarse format, has come
    # down from it: the samples before that run the coarse path, and c_e's level starts at the largest
    # |c_e| after a settling stretch of the run (c_r, c_v, c_a: at their largest over the whole run)
    head, tail = _start_run(d, p.n_run, 1024)
    theta0 = np.asarray(g.max_c, dtype=float) * cs
    theta0[3] = tail[3] if p.n_run > len(head) else float(np.abs(head[-1, 0, 3]))
    lengths = sorted({1 << j for j in range(0, max(1, gap).bit_length(), 4) if 1 << j < gap} | {gap})
    P0 = np.array([P for _, P in g.checkpoints])
    # per trajectory set: the updated samples of every trajectory, |c| posterior (m, ncp, 4), and the
    # largest |c| prior and S of the samples after each one (m, ncp, 5; the last row: what follows)
    runs = []
    for after, rest in [(_gap_trajectories(d, P0, L, 4 * L + 50), np.zeros(5)) for L in lengths] + [(head, tail)]:
        after[:, :, :4] = np.abs(after[:, :, :4] * cs)  # prior c (m, ncp, 4: r, u, a, e), S (m, ncp, 1)
        post = after[:, :, :4] * (R / after[:, :, 4:])  # posterior c = c R / S
        np.maximum.accumulate(after[::-1], axis=0, out=after[::-1])  # in place: the largest from each on
        after[:-1] = after[1:]  # ... after each sample
        after[-1] = rest * np.r_[cs, 1.0]
        after[:-1] = np.maximum(after[:-1], after[-1])
        runs.append((post, after))

    def tops(theta: np.ndarray) -> np.ndarray:
        """Largest (|c_r|, |c_v|, |c_a|, |c_e|, S) of the fine samples when the switch is at theta."""
        top = np.r_[theta0, g.S_max]
        for post, after in runs:
            ok = np.all(post <= theta, axis=2)  # (m, ncp)
            j = np.argmax(ok, axis=0)  # per trajectory the update that switches; then every prior is fine
            cols = np.flatnonzero(ok[j, np.arange(ok.shape[1])])
            if len(cols):
                jj = j[cols]
                top = np.maximum(top, np.r_[post[jj, cols].max(0), 0.0])
                top = np.maximum(top, after[jj, cols].max(0))
        return top

    top = tops(theta0)
    bounds = {"cr": top[0], "cv": top[1], "ca": max(top[2], top[4]), "ce": top[3]}
    omp = 1.0 - d.phi
    # the predict sums of codegen.emit_c._predict_cov stay single SMLAL chains into the high word when
    # each constant, scaled to land its product there, keeps below 2^30: (constant, its variable's frac)
    terms = {
        "ca": [(omp, p.f("Pae"))],
        "cv": [(Ts * Ts, "ca"), (omp, p.f("Pve"))],
        "cr": [(Ts * Ts / 2, "ca"), (omp, p.f("Pre")), (1.0, "cv")],
        "ce": [(d.phi * omp, p.f("Pae"))],
    }
    fracs: dict[str, int] = {}
    for nm in ("ca", "cv", "cr", "ce"):
        c = p.vars[nm]
        f = max(fit(GUARD * bounds[nm], 32).frac, c.fmt.frac)
        while f > c.fmt.frac and any(
            val * 2.0 ** (f + 32 - (fracs[fv] if isinstance(fv, str) else fv)) >= 2**30 for val, fv in terms[nm]
        ):
            f -= 1
        fracs[nm] = f
    # the largest value each fine format holds with GUARD: c_r, c_v, c_a, c_e, S (S in c_a's)
    room = np.array([2.0 ** (31 - fracs[nm]) * (1 - 2.0**-20) / GUARD for nm in ("cr", "cv", "ca", "ce", "ca")])
    theta = np.maximum(theta0, room[:4] / 2)
    for _ in range(64):
        over = tops(theta) > room
        over = over[:4] | np.array([False, False, over[4], False])
        if not over.any():
            break
        theta = np.where(over, np.maximum(theta0, theta / 2), theta)
    else:
        theta = theta0
    top = tops(theta)
    if np.any(top > room):  # theta0 itself: the formats were chosen to hold it
        raise AssertionError(f"fine formats do not hold {top} within {room}")
    return fracs, theta, top


def fine_view(p: AxisPlan) -> AxisPlan:
    """The plan with the fine formats of c_r, c_v, c_a, c_e and S (and R in S's) under their usual names:
    what the covariance form's common path is emitted from."""
    import copy

    q = copy.copy(p)
    q.vars = dict(p.vars)
    for nm in (*FINE, "S"):
        q.vars[nm + "_c"] = p.vars[nm]  # the coarse ones stay readable
        q.vars[nm] = p.vars[nm + "_f"]
    q.sat_free = _predict_sat_free(q)  # c_e's predict: its own check in the fine format
    return q


def _predict_sat_free(p: AxisPlan) -> frozenset:
    """The predict sums of the covariance block that fit int32 whatever int32 values the carried
    entries hold, so they need no saturation: no assumption about the data, the skip pattern or the
    history (the entries are bounded only by their words).

    c_e' = phi^2 c_e + phi (1 - phi) P_ae + Q_ee, formed in the C (codegen.emit_c._predict_terms) as
    one rounding of the three terms, each aligned (floor) to a few guard bits below c_e's LSB. For
    |c_e|, |P_ae| <= 2^31 it stays below (phi^2 + phi (1 - phi)) 2^31 = phi 2^31 plus Q_ee and a few
    LSB of flooring and rounding (codegen.qformat.acc_bound adds them up exactly): phi < 1 leaves
    (1 - phi) 2^31 LSB of room, which the model's Q_ee must not use up.

    Every other sum adds to an entry that can sit anywhere in its word (c_a += Q_aa each skipped
    sample; P_re, P_ve follow the unbounded P_ue through gaps of any length): those keep their clamps.
    """
    from .qformat import acc_bound, quantize

    def qi(name):
        val, fmt = p.consts[name]
        return abs(quantize(val, fmt)), fmt.frac

    fce, fPae = p.f("ce"), p.f("Pae")
    phi2, f2 = qi("PHI2")
    po, fpo = qi("PHIOMP")
    qee, fq = qi("Qee")
    free = set()
    if min(f2, fpo + fPae - fce, fq - fce) > 0:  # all three finer than c_e, as emitted
        if acc_bound(fce, [(phi2 * 2**31, f2 + fce), (po * 2**31, fpo + fPae), (qee, fq)]) <= 2**31 - 1:
            free.add("ce")
    return frozenset(free)


# gain schedule after a skip: the deviation of the covariance block from the schedule's (codegen.follow)
DEV = ("Dcr", "DPre", "Dcv", "DPve", "Dca", "DPae", "Dce")
DEV_GUARD = 4.0  # |D| <= |P| + |P_u| <= 2 max|P| over the gaps, times the plan's GUARD


def _plan_schedule_follow(p: AxisPlan) -> None:
    """Gain-schedule form: formats of the deviation block that codegen.follow carries after a skip, of S
    and of the predict constants."""
    g, gg, Ts = p.gains, p.gap_run, p.design.Ts
    pm = np.maximum(np.maximum(g.max_prior, g.max_post), np.maximum(gg.max_prior, gg.max_post))
    mc = np.maximum(g.max_c, gg.max_c)
    s_max = max(g.S_max, gg.S_max, float(mc[2]))
    bounds = {
        "Dcr": mc[0],
        "DPre": pm[3],
        "Dcv": Ts * mc[1],
        "DPve": Ts * pm[4],
        "Dca": s_max,
        "DPae": pm[5],
        "Dce": mc[3],
    }
    notes = {
        "Dcr": "c_r = P_ra + P_re",
        "DPre": "P_re",
        "Dcv": "c_v = Ts (P_ua + P_ue)",
        "DPve": "Ts P_ue",
        "Dca": "c_a = P_aa + P_ae",
        "DPae": "P_ae",
        "Dce": "c_e = P_ae + P_ee",
    }
    for nm, b in bounds.items():
        f = _require(p.model, f"gain schedule: deviation of {notes[nm]}", "(SI units squared)", DEV_GUARD * b, 32)
        p.vars[nm] = Var(nm, "cov", DEV_GUARD * b, f, f"deviation from the schedule's block: {notes[nm]}", True)
    fS = _require(p.model, "gain schedule: S", "(m/s^2)^2", GUARD * s_max, 32)
    p.vars["S"] = Var("S", "(m/s^2)^2", GUARD * s_max, fS, "H P H' + R after a skip, >= R", True)
    d = p.design
    p.consts["PHI"] = (d.phi, QFormat(32, 31))
    p.consts["PHI2"] = (d.phi**2, QFormat(32, 31))
    p.consts["PHIOMP"] = (d.phi * (1 - d.phi), const_format(d.phi * (1 - d.phi)))
    p.consts["R"] = (d.R, fS)
    from .qformat import quantize

    R_int = quantize(d.R, fS)
    if R_int < 2**12 or d.R / s_max * 2**30 < 2:  # S_u = R / (1 - K_a - K_e), 1 - K_a - K_e in Q.30
        raise RangeError(
            p.model.source,
            "noise.R",
            f"R = {d.R:.6g} is {R_int} LSB of the gain schedule's S format {fS}; needs at least 13 bits below "
            f"the largest S {s_max:.6g}",
        )
