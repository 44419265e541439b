"""The planner: every number the fixed-point emitter writes, computed and checked before any C exists.

:func:`plan` takes a model to one :class:`AxisCode` per axis: the Q formats and bounds of
:func:`codegen.ranges.plan_axis`, the gain schedule (gain-schedule form), the quantised constants and
initial state, the clamp words, the offset of the gain schedule's bias state, its step after a skip
(:class:`codegen.follow.FollowPlan`: return thresholds and every shift), the covariance form's sums
(:mod:`codegen.plan_cov`: constants folded, shifts, guard bits, saturations) and the state's layout and
checkpoint image (:mod:`codegen.layout`). Every refusal of a model whose ranges the C cannot carry is
raised here, as a :class:`~codegen.ranges.RangeError`, so :mod:`codegen.emit_c` only formats a plan that
is known to fit.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from accelnav.model.load import Model

from .gains import Schedule
from .layout import Layout, layout
from .plan_cov import CovSums, cov_fracs, cov_sums
from .qformat import QFormat, quantize
from .ranges import FINE, AxisPlan, RangeError, fine_view, plan_axis

# K_r, K_v (no feedback: 3e-4 and 1e-3 took the 100 Hz table from 259 to 177 segments, 1 kHz from 673 to
# 412, the firmware's departure from the float64 filter on the shock and stress lockstep runs unchanged
# within 1e-4 sigma; K_r at 1e-3 halved it again but moved u after a gap from 2e-4 to 8.4e-4 sigma, the
# schedule's largest K_r error being the threshold at which codegen.follow returns to the schedule),
# K_a (held in a segment: tight; it sets how the innovation splits between a and eps, a mode that
# decays over ~1/K_e samples: 2e-7, about 5 % of K_e, left a at 9.5e-4 sigma on shock and stress
# at 100 Hz over 13 seeds, 1e-7 4.5e-4 with the same segment counts at 100 Hz and 1 kHz), K_e (as before)
SCHEDULE_REL_TOL = (3e-4, 1e-3, 1e-7, 1e-4)
# tolerance floor of each gain in LSB of its format: K_r's slope is a whole number of LSB per sample (no
# bits below it), so under ~1 LSB of tolerance a segment lasts only a few samples wherever the true slope
# is not near a whole number (at 1 kHz K_r is ~3e4 LSB from 0.1 s to 10 s: 751 of the 1084 segments).
# Measured (tests/codegen/test_codegen.py lockstep, 1 kHz shock): r and u stay within 4.2e-4 sigma with 2 LSB.
SCHEDULE_FLOOR_LSB = (2.0, 0.0, 0.0, 0.0)
# K_r and K_v's tolerance ramps up from 1/20 over the first this many seconds (codegen.gains.schedule;
# codegen.follow's return threshold follows the same ramp)
SCHEDULE_RAMP_S = 10.0

RECIP_TABLE_BITS = 7  # the covariance form's reciprocal starts from a table of 2^7 entries


def schedule_for(p: AxisPlan) -> Schedule:
    """The plan's gain schedule over its declared run, computed window by window (memory does not grow
    with the run)."""
    from .gains import schedule_of

    fm = tuple(p.vars["K" + n].fmt for n in "rvae")
    return schedule_of(
        p.design,
        p.n_run,
        fm,
        SCHEDULE_REL_TOL,
        ramp=int(SCHEDULE_RAMP_S * p.model.rate_hz),
        floor=SCHEDULE_FLOOR_LSB,
    )


def _thumb_imm(x: int) -> bool:
    """x is a Thumb-2 modified immediate of the shifted-byte kind (an 8-bit value shifted left)."""
    if x == 0:
        return True
    while x % 2 == 0:
        x //= 2
    return x < 256


def clamp_word(bound: float, fmt, step: float) -> int:
    """High-word clamp h >= bound (in 2^32 LSB of fmt) of acn_limit; rounded up to a value whose
    double is a Thumb-2 immediate (one ADD and one CMP with immediates, no literal loads) when
    h 2^32 plus one step still fits the int64 (the format was chosen to hold bound + step)."""
    h = math.ceil(bound * 2.0 ** (fmt.frac - 32))
    k = max(0, h.bit_length() - 8)
    hi = -(-h >> k) << k  # h rounded up to 8 significant bits
    if _thumb_imm(2 * hi) and 2 * hi < 2**32 and hi * 2.0**32 + step * 2.0**fmt.frac < 2.0**63 - 2.0**40:
        return hi
    return h


def recip_table(nb: int = RECIP_TABLE_BITS) -> list[int]:
    """acn_rtab: entry i is 2^30 / D at the middle of D in [1/2 + i 2^-(nb+1), 1/2 + (i+1) 2^-(nb+1)),
    Q2.30 >> 15."""
    return [round(2**30 / (0.5 + (i + 0.5) / 2 ** (nb + 1)) / 2**15) for i in range(2**nb)]


@dataclass(frozen=True)
class Merge:
    """How the gain schedule's step sums r's and v's increments (codegen.emit_c._core_fixed)."""

    h2_apart: bool  # Ts^2/2 a shifted into r apart from K_r y's accumulator (formats differ)
    t2_apart: bool  # Ts^2 a shifted into v apart from K_v y's accumulator
    a_in_v: bool  # Ts^2/2 in v's product format: w = v + Ts^2/2 a starts both increments
    merge_v: bool  # r's increment v + Ts^2/2 a + K_r y in one accumulator, Q.fp
    onto_v: bool  # v's increment Ts^2 a + K_v y accumulated onto v itself
    fp: int  # frac bits of r's increment accumulator (K_r y's)


def gs_merge(p: AxisPlan, vhi: int) -> Merge:
    """The gain schedule's sums for this plan's formats; ``vhi``: v's high-word clamp."""
    fv, fy = p.f("v"), p.f("y")
    fK = {n: p.f("K" + n) for n in "rv"}
    h2_apart = p.consts["H2"][1].frac != fK["r"]
    t2_apart = p.consts["T2"][1].frac != fK["v"]
    # Ts^2/2 in v's product format (codegen.ranges, when K_r's would leave it too few bits): w = v + Ts^2/2 a
    # in Q.fv (one SMLAL) starts both increments, r's shifted, v's with the rest (Ts^2 - Ts^2/2) a
    a_in_v = h2_apart and p.consts["H2"][1].frac + fy == fv
    if a_in_v:
        h2_apart = False
    # r's increment v + Ts^2/2 a + K_r y in one accumulator (Q.fp, one SMLAL each) when v's format is at
    # least as fine and the sum cannot leave int64: v at its clamp, a and y at their range bounds
    fp = fK["r"] + fy
    v_hi = vhi * 2.0 ** (32 - fv)
    p_max = v_hi + (0 if h2_apart else p.consts["H2"][0] * p.vars["a"].bound)
    p_max += p.vars["Kr"].bound * p.vars["y"].bound
    merge_v = fv >= fp and p_max * 2.0**fp < 2.0**62
    # v's own increment Ts^2 a + K_v y accumulated onto v when it is already in v's format (the same sum)
    onto_v = not t2_apart and fK["v"] + fy == fv
    if a_in_v and not (merge_v and onto_v and (v_hi + p.consts["H2"][0] * p.vars["a"].bound) * 2.0**fv < 2.0**63):
        raise ValueError("Ts^2/2 a onto v needs v in r's and v's increments and v + Ts^2/2 a within int64")
    return Merge(h2_apart, t2_apart, a_in_v, merge_v, onto_v, fp)


@dataclass(frozen=True)
class AxisCode:
    """One axis as the emitter writes it: the plan of formats and every integer the C carries."""

    p: AxisPlan
    consts: dict[str, tuple[float, QFormat, int]]  # name: (value, format, its quantised integer)
    clamps: dict[str, tuple[str, float, int]]  # RHI / VHI: (state, bound, high-word clamp)
    x0: tuple[int, int, int, int]  # r, v = Ts u, a, eps in their formats
    cov0: dict[str, tuple[float, int]]  # covariance form: the initial block of P (value, integer)
    eoff: int | None  # gain schedule: eps = eb + eoff (LSB of e); None: the state holds eps
    sched: Schedule | None  # gain schedule: its table
    follow: object | None  # gain schedule: codegen.follow.FollowPlan of the step after a skip
    merge: Merge | None  # gain schedule: how its step sums the increments
    layout: Layout  # the state struct and its checkpoint image
    cov: tuple[CovSums, CovSums] | None = None  # covariance form: its sums in the fine and coarse formats
    switch: dict[str, int] | None = None  # covariance form: the switch levels theta in LSB of the coarse formats


def _eps_offset(p: AxisPlan) -> int:
    """The gain schedule's eps offset (eps = eb + EOFF), with the invariants its state relies on."""
    fe = p.f("e")
    if fe != p.f("y") + 32 or p.consts["EBAR"][1].frac != p.f("y") or p.f("z") != p.f("y"):
        raise ValueError("eb needs eps in Q.(fy + 32) and z, eps_bar in Q.fy")
    if p.n_run >= 2**30:  # the schedule ends within the run: a count restarted at 2^30 is past it
        raise ValueError("the gain schedule's run must stay below 2^30 samples (k restarts there)")
    eoff = quantize(p.consts["EBAR"][0], p.consts["EBAR"][1]) * 2**32 - 2**31
    big = p.vars["e"].bound * 2.0**fe + abs(eoff) + 2.0**32
    if big >= 2.0**63:
        raise ValueError(f"eb = eps - eps_bar + 1/2 LSB leaves int64 ({big:.3g} LSB)")
    return eoff


def _follow(p: AxisPlan, sched: Schedule):
    """The follow step after a skip (codegen.follow.FollowPlan: its return thresholds and every shift),
    once the deviation's shifts are known to fit this model."""
    from .follow import follow_plan, thresholds

    try:
        return follow_plan(p, thresholds(sched))
    except ValueError as e:  # a shift the deviation's formats cannot take: this model's ranges
        raise RangeError(p.model.source, "filter.form", f"'gain_schedule' after a skip: {e}") from None


def _check_cov_shifts(p: AxisPlan) -> None:
    """The covariance update's right shifts (codegen.emit_c._gains_cov) lie in 1..62 for these formats."""
    cf = cov_fracs(p)
    fx, fca, fy = cf["x"], p.f("ca"), p.f("y")
    sw = fy + fx - p.f("w")
    for what, sh in (("kappa", fca + fx - 31), ("K_e", p.f("ce") + fx - p.f("Ke")), ("w", sw),
                     ("a", cf["prod"]["a"] - fy)):  # fmt: skip
        if not 1 <= sh <= 62:
            raise ValueError(f"{what} shift {sh} out of range")


def _cov0(p: AxisPlan) -> dict[str, tuple[float, int]]:
    d = p.design
    P0, Ts = d.P0, d.Ts
    vals = {
        "cr": P0[0, 2] + P0[0, 3],
        "Pre": P0[0, 3],
        "cv": Ts * (P0[1, 2] + P0[1, 3]),
        "Pve": Ts * P0[1, 3],
        "ca": P0[2, 2] + P0[2, 3],
        "Pae": P0[2, 3],
        "ce": P0[2, 3] + P0[3, 3],
    }
    return {nm: (val, quantize(val, p.vars[nm].fmt)) for nm, val in vals.items()}


def axis_code(p: AxisPlan) -> AxisCode:
    """Everything the emitter needs of one planned axis; raises what the model's ranges cannot carry."""
    d, v = p.design, p.vars
    if any(d.x0[:3]):  # both forms' steps drop the increments of the first sample
        raise ValueError("the merged predict needs r, u, a of x0 at zero")
    consts = {name: (value, fmt, quantize(value, fmt)) for name, (value, fmt) in p.consts.items()}
    clamps = {
        nm: (key, v[key].bound, clamp_word(v[key].bound, v[key].fmt, step))
        for nm, key, step in (("RHI", "r", p.step_max), ("VHI", "v", p.v_step))
    }
    x0 = (
        quantize(d.x0[0], v["r"].fmt),
        quantize(d.Ts * d.x0[1], v["v"].fmt),
        quantize(d.x0[2], v["a"].fmt),
        quantize(d.x0[3], v["e"].fmt),
    )
    if p.form == "gain_schedule":
        sched = schedule_for(p)
        merge = gs_merge(p, clamps["VHI"][2])
        return AxisCode(p, consts, clamps, x0, {}, _eps_offset(p), sched, _follow(p, sched), merge, layout(p.form))
    views = (fine_view(p), p)  # the predict and update in the fine and in the coarse formats
    for q in views:
        _check_cov_shifts(q)
    cov = tuple(cov_sums(q) for q in views)
    switch = {nm: math.floor(p.theta[nm] * 2.0 ** p.vars[nm].fmt.frac) for nm in FINE}
    return AxisCode(p, consts, clamps, x0, _cov0(p), None, None, None, None, layout(p.form), cov, switch)


def plan(model: Model, form: str | None = None) -> list[AxisCode]:
    """Every axis of ``model`` planned and checked: the axes at once, on two threads (their Riccati
    recursions and schedule searches run in C, off the interpreter lock; the schedules land in
    codegen.gains' cache for the report)."""

    def one(i: int) -> AxisCode:
        return axis_code(plan_axis(model, i, form))

    with ThreadPoolExecutor(max_workers=2) as pool:
        return list(pool.map(one, range(len(model.axes))))
