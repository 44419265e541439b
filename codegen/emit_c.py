"""Emit C from a model: ``emit(model, ...) -> {filename: text}``.

Pure: no file is written here (host/cli/codegen.py does that). The C is the
filter of DESIGN.md for every axis of the model, in one of two forms
(covariance: the seven-entry block of P in fixed point; gain_schedule: the
float64 gains compressed into a piecewise-linear table) and one of two
arithmetics (fixed point from :mod:`codegen.ranges`, or float32).

Every step is straight-line 32x32 -> 64 arithmetic (SMULL/SMLAL on a
Cortex-M3): the formats of :mod:`codegen.ranges` are chosen so that most
products need no shift or a single one, clamps run once per step and only on
r and u (the two states no analysis bounds), and the gain schedule keeps K_r,
K_v, K_a in int32 and K_e in an int64 accumulator (its slope falls far below
one LSB of K_e as it settles).

The header carries the plain declarations between ``ACCELNAV-CDEF-BEGIN`` /
``ACCELNAV-CDEF-END`` so that the cffi harness builds from exactly them.
"""

from __future__ import annotations

import contextvars
import functools
import re

from accelnav.model.design import AnalogConversion
from accelnav.model.load import Model
from accelnav.resources import package_dir

from .emit_f32 import emit_f32
from .layout import C_SIZES, COV_BLOCK, SEG, state_members, struct_offsets
from .package import cdef_of, check_prefix, package, write  # noqa: F401  (cdef_of, write: re-exported for callers)
from .plan import (  # noqa: F401  (the schedule's settings and schedule_for: re-exported for tests and bench/)
    RECIP_TABLE_BITS,
    SCHEDULE_FLOOR_LSB,
    SCHEDULE_RAMP_S,
    SCHEDULE_REL_TOL,
    AxisCode,
    plan,
    recip_table,
    schedule_for,
)
from .plan_cov import Acc, CovSums, HSum, Term
from .ranges import DEV, FINE, AxisPlan, refuse_calibrated
from .share import Shared, merge

# Every shift written out, even by zero: the axes' steps then line up token by token (codegen.share).
_EXPLICIT_SHIFTS = contextvars.ContextVar("explicit_shifts", default=False)


def _c_int(v: int, word: int) -> str:
    if word == 64:
        if v == -(2**63):
            return "INT64_MIN"
        return f"INT64_C({v})"
    if v == -(2**31):
        return "INT32_MIN"
    return f"INT32_C({v})"


def _shift(expr: str, frm: int, to: int, comment: str = "") -> str:
    """expr (int64, frac bits frm) -> frac bits to, rounded to nearest."""
    s = frm - to
    if s >= 64:  # |expr| < 2^63 contributes less than one LSB of the target: below its resolution
        return f"0 /* ({expr}) Q.{frm} -> Q.{to}: below one LSB, dropped */"
    c = f" /* Q.{frm} -> Q.{to}, round{comment} */" if s > 0 else f" /* Q.{frm} -> Q.{to}, exact */"
    if s > 0:
        return f"ACN_RSHR({expr}, {s}){c}"
    if s == 0:
        return f"({expr}){c}"
    return f"(({expr}) * ((int64_t)1 << {-s})){c}"


_PRODUCT = re.compile(r"\(int64_t\)(-?[A-Za-z_][\w>.-]*) \* ([A-Za-z_][\w>.-]*)")


def _smull(line: str) -> str:
    """(int64_t)a * b of two int32 -> acn_mul(a, b)."""
    return _PRODUCT.sub(r"acn_mul(\1, \2)", line)


def _fixed_consts(c: AxisCode, P: str) -> list[str]:
    out = []
    for name, (value, fmt, q) in sorted(c.consts.items()):
        lit = f"UINT32_C({q})" if fmt.word == 33 else _c_int(q, fmt.word)  # 33: an unsigned 32-bit mantissa
        out.append(f"#define {P}_{name} {lit} /* {value:.17g} {'UQ0.' + str(fmt.frac) if fmt.word == 33 else fmt} */")
    return out


def _fields_fixed(p: AxisPlan, T: str) -> list[tuple[str, str, str]]:
    """(C type, name, comment) of the state's members, in the planned order (codegen.layout)."""
    v = p.vars
    com = {
        "r": f"r [m] {v['r'].fmt}",
        "v": f"Ts*u [m] {v['v'].fmt}",
        "e": f"eps [m/s^2] {v['e'].fmt}",
        # eps carried with eps_bar and the rounding of its high word folded in
        "eb": f"eps - eps_bar + 2^-{p.f('y') + 1} [m/s^2] {v['e'].fmt} (read() gives eps)",
        "a": f"a [m/s^2] {v['a'].fmt}",
        "seg": "the schedule's current row",
        "z": "the deviation entries hold D 2^z (codegen.follow.ZOOM_MAX)",
        "overflow": "saturations so far",
    }
    if p.form == "covariance":
        com |= {nm: f"{v[nm].note.split(',')[0]} {v[nm].fmt}" for nm in COV_BLOCK}
        com["k"] = "2 x samples since init, + 1 while c_r, c_v, c_a, c_e are in their fine formats"
    else:
        com |= {"K" + nm: f"K_{nm} of the next sample {v['K' + nm].fmt}" for nm in "rv"}
        com["Ke_lo"] = f"K_e accumulator, low word (Q.{v['Ke'].fmt.frac + 32} with Ke)"
        com["Ke"] = f"K_e of the next sample {v['Ke'].fmt}: the accumulator's high word"
        com |= {nm: f"{v[nm].note} {v[nm].fmt}" for nm in DEV}
        com["k"] = "samples since init (bit 31: following a skip, codegen.follow)"
    return [(f"const struct {T}_seg_s *" if t == SEG else t, nm, com[nm]) for t, nm in state_members(p.form)]


_struct_offsets = struct_offsets  # its name before codegen.layout: tests import it from here


def _fields_checkpoint(fields: list[tuple[str, str, str]], T: str) -> list[tuple[str, str, str]]:
    """The members of a checkpoint image (T_save, T_load): the state's, in its order, with the gain
    schedule's row pointer as its index in T_seg: the same bytes on every target."""
    return [
        ("uint32_t", nm, f"the schedule's current row, as its index in {T}_seg") if nm == "seg" else (t, nm, c)
        for t, nm, c in fields
    ]


def _checkpoint_c(c: AxisCode, P: str, T: str, fields: list[tuple[str, str, str]]) -> list[str]:
    """C of T_save and T_load: the state to and from its checkpoint image of P_CK_BYTES bytes (the
    telemetry's checkpoint frames, accelnav.link.replay): every member little-endian at its offset under
    natural alignment, which is the covariance state struct's own bytes on a little-endian target; the
    gain schedule's row pointer goes as its index in T_seg. T_load refuses an index outside the table
    (and leaves the state as it was), so no image makes the filter read past it. Only checkpoints call
    these, never the step."""
    ck = _fields_checkpoint(fields, T)
    off = c.layout.ck_offsets
    gs = c.p.form == "gain_schedule"

    def put(t, nm):
        o = off[nm]
        if nm == "seg":
            return [f"    acn_put32(out + {o}, (uint32_t)(s->seg - {T}_seg)); /* the row's index, 0 .. {P}_NSEG */"]
        if C_SIZES[t] == 8:
            return [
                f"    acn_put32(out + {o}, (uint32_t)(uint64_t)s->{nm}); /* {nm}, low word */",
                f"    acn_put32(out + {o + 4}, (uint32_t)((uint64_t)s->{nm} >> 32));",
            ]
        return [f"    acn_put32(out + {o}, (uint32_t)s->{nm});"]

    def get(t, nm):
        o = off[nm]
        if nm == "seg":
            return [f"    s->seg = &{T}_seg[row];"]
        if C_SIZES[t] == 8:
            return [f"    s->{nm} = ({t})((uint64_t)acn_get32(in + {o + 4}) << 32 | acn_get32(in + {o}));"]
        return [f"    s->{nm} = ({t})acn_get32(in + {o});"]

    what = "with the row as its index in the table" if gs else "the state struct's bytes on a little-endian target"
    src = [f"/* The checkpoint image ({P}_CK_BYTES bytes, {what}). */"]
    if not gs:  # on AVR (little-endian, no padding) the image is the struct's bytes: copied, not built member by member
        same = " && ".join(f"offsetof({T}_t, {nm}) == {off[nm]}" for _, nm, _ in ck)
        src += [
            "#if defined(__AVR__)",
            "/* the image's layout is the struct's here (a compile error if not): a copy byte by byte, a few dozen",
            " * instructions where the members one by one took some 900 bytes of the part's flash */",
            f"typedef char {T}_ck_is_the_struct[sizeof({T}_t) == {P}_CK_BYTES && {same} ? 1 : -1];",
            f"void {T}_save(const {T}_t *s, uint8_t *out)",
            "{",
            "    const uint8_t *p = (const uint8_t *)s;",
            f"    for (unsigned i = 0; i < {P}_CK_BYTES; i++) {{",
            "        out[i] = p[i];",
            "    }",
            "}",
            "",
            f"bool {T}_load({T}_t *s, const uint8_t *in)",
            "{",
            "    uint8_t *p = (uint8_t *)s;",
            f"    for (unsigned i = 0; i < {P}_CK_BYTES; i++) {{",
            "        p[i] = in[i];",
            "    }",
            "    return true;",
            "}",
            "#else",
        ]
    src += [f"void {T}_save(const {T}_t *s, uint8_t *out)", "{"]
    for t, nm, _ in ck:
        src += put(t, nm)
    src += ["}", ""]
    if gs:
        src += [
            "/* false (s untouched) for a row index outside the table or a deviation zoom past ZOOM_MAX: a damaged",
            " * image, never a firmware's. */",
        ]
    src += [f"bool {T}_load({T}_t *s, const uint8_t *in)", "{"]
    if gs:
        from .follow import ZOOM_MAX

        src += [
            f"    uint32_t row = acn_get32(in + {off['seg']});",
            f"    if (row > (uint32_t){P}_NSEG || acn_get32(in + {off['z']}) > {ZOOM_MAX}u) {{",
            "        return false; /* a row outside the table, or a zoom no shift can take */",
            "    }",
        ]
    for t, nm, _ in ck:
        src += get(t, nm)
    src += ["    return true;", "}"] + ([] if gs else ["#endif"]) + [""]
    return src


def _input_fixed(p: AxisPlan, P: str) -> tuple[str, str, list[str]]:
    """(parameter list, argument list, body lines computing `valid` and `z`)."""
    fz = p.f("z")
    if isinstance(p.conv, AnalogConversion) and p.conv_shift >= 0:
        fs = p.consts["SCALE"][1].frac
        body = [
            f"    /* rails: codes 0 and {p.conv.full_code} are clipped */",
            f"    if (code <= 0 || code >= {p.conv.full_code}) {{",
            "        return false;",
            "    }",
            f"    /* z = code * scale + offset: (code << {p.conv_shift}) x SCALE (Q.{fs}, unsigned) is"
            f" Q.{fs + p.conv_shift}, its high word Q.{fz} (floor;",
            "     * OFFSET carries half an LSB, so the sum rounds) */",
            f"    *z = (int32_t)acn_umulhi((uint32_t)code << {p.conv_shift}, {P}_SCALE) + {P}_OFFSET;",
            "    return true;",
        ]
        return "int32_t code", "code", body
    if isinstance(p.conv, AnalogConversion):
        cs = p.consts["SCALE"][1]
        body = [
            f"    /* rails: codes 0 and {p.conv.full_code} are clipped */",
            f"    if (code <= 0 || code >= {p.conv.full_code}) {{",
            "        return false;",
            "    }",
            f"    /* z = code * scale + offset: Q.{cs.frac} (int64) -> {p.vars['z'].fmt} */",
            f"    *z = (int32_t){_shift(f'(int64_t)code * {P}_SCALE + {P}_OFFSET', cs.frac, fz)};",
            "    return true;",
        ]
        return "int32_t code", "code", body
    nom = p.conv.t2_nominal
    cg = p.consts["DGAIN"][1]
    body = [
        "    int n;",
        "    uint32_t x;",
        "    int32_t duty;",
        f"    /* invalid: no period, period off the nominal {nom} counts by more than 25 %, output stuck */",
        f"    if (t2 <= 0 || t1 <= 0 || t1 >= t2 || (int64_t)4 * t2 - {4 * nom} > {nom} ||"
        f" (int64_t)4 * t2 - {4 * nom} < -{nom}) {{",
        "        return false;",
        "    }",
        "    /* duty = t1 / t2 without a division: 1/t2 = x 2^(n-62) */",
        "    x = acn_recip((uint32_t)t2, &n);",
        "    duty = acn_rshr32((int64_t)acn_umul((uint32_t)t1, x), 31 - n); /* Q(62-n) -> Q0.31, round (t1 > 0) */",
        f"    /* z = duty * g0/duty_per_g - zero_g * g0/duty_per_g: Q.{31 + cg.frac} -> {p.vars['z'].fmt} */",
        f"    *z = acn_rshr32(acn_mac(-{P}_DZERO, duty, {P}_DGAIN), {31 + cg.frac - fz}); /* Q.{31 + cg.frac} ->"
        f" Q.{fz}, round */"
        if 1 <= 31 + cg.frac - fz <= 63 and cg.word == 32 and p.consts["DZERO"][0] > -(2.0**62)  # -DZERO fits int64
        else f"    *z = (int32_t){_shift(f'(int64_t)duty * {P}_DGAIN - {P}_DZERO', 31 + cg.frac, fz)};",
        "    return true;",
    ]
    return "int32_t t1, int32_t t2", "t1, t2", body


def _mul_round32(a: str, b: str, frm: int, to: int, comment: str = "") -> str:
    """(a b: int32 x int32, frac bits frm) -> frac bits to, rounded to nearest, as an int32 (its low word
    where it does not fit: the caller's int32 arithmetic wraps). One call on every target
    (acn_mul_rshr32: on AVR a product and a byte-wise shift instead of libgcc's 64-bit helpers)."""
    s = frm - to
    if 1 <= s <= 63:
        return f"acn_mul_rshr32({a}, {b}, {s}) /* Q.{frm} -> Q.{to}, round{comment} */"
    return f"(int32_t){_shift(f'acn_mul({a}, {b})', frm, to, comment)}"


def _sh(expr: str, s: int, what: str) -> str:
    """expr (int64) >> s, floor (arithmetic shift); s <= 0 multiplies. Comment: what it converts."""
    if s > 0 or (s == 0 and _EXPLICIT_SHIFTS.get()):
        return f"(({expr}) >> {s}) /* {what}, floor */"
    if s == 0:
        return f"({expr}) /* {what}, exact */"
    return f"(({expr}) * ((int64_t)1 << {-s})) /* {what}, exact */"


def _hi_round(expr: str) -> str:
    """The high word of an int64, rounded to nearest (ties up)."""
    return f"acn_hi_round({expr})"


def _term(t: Term, P: str) -> str:
    """C of one term of a planned sum (codegen.plan_cov.Term)."""
    if t.const is None:
        return f"(int64_t){t.var}"
    c = f"(int64_t){'-' if t.neg else ''}{P}_{t.name}"
    return f"{c} * {t.var}" if t.var else c


def _acc(a: Acc, P: str) -> str:
    """C of a sum rounded once (codegen.plan_cov.Acc): the terms already in Q.ft add exactly; the finer
    ones are aligned (floor) to Q.(ft + g) (each fine term a product of two int32, neither INT32_MIN, or
    an int32 constant, so |term| < 2^62 and two of them plus the rounding offset stay below 2^63), summed,
    and rounded once to Q.ft.

    The rounding adds half an LSB (to nearest, ties up), or with a dither (the C name of a uint32 that
    runs through its values evenly from sample to sample: the bit-reversed sample count) its top g bits:
    still one floor of the sum plus an offset below one LSB, so the result is within one LSB of the
    exact sum, but an increment that holds a steady fraction of an LSB for many samples is no longer
    rounded the same way every time: over any 2^m consecutive samples the roundings add up to at most
    about one LSB instead of up to 2^m / 2 (used on the entries whose own change per sample is a small
    fraction of their LSB)."""
    ft, g = a.ft, a.g
    out = " ".join(f"{t.sign} {_term(t, P)}" for t in a.exact).lstrip("+ ")
    if a.fine:
        parts = " ".join(
            f"{t.sign} " + (f"(({_term(t, P)}) >> {sh})" if sh or _EXPLICIT_SHIFTS.get() else f"({_term(t, P)})")
            for t, sh in a.fine
        )
        if a.dither is not None:
            off = f"(int64_t)({a.dither} >> {32 - g})" if g < 32 else f"(int64_t){a.dither}"
            out += f" + (({parts.lstrip('+ ')} + {off}) >> {g}) /* in Q.{ft + g}, dithered once to Q.{ft} */"
        else:
            out += f" + ACN_RSHR({parts.lstrip('+ ')}, {g}) /* in Q.{ft + g}, rounded once to Q.{ft} */"
    return f"({out})"


def _hsum(h: HSum) -> str:
    """C of a sum in one int64 accumulator whose high word is the int32 result (codegen.plan_cov.HSum):
    the folded constants and the rounding offset (half an LSB, or the dither) start it, then one SMLAL
    per variable."""
    acc = f"INT64_C({h.lit}) + (int64_t){h.dither}" if h.dither else _c_int(h.lit + 2**31, 64)
    if not h.ops:
        return f"(int32_t)(({acc}) >> 32) /* Q.{h.F} -> Q.{h.ft}, high word */"
    for i, (x, k, ki, (val, q)) in enumerate(h.ops):
        cm = f"2^{q}" if val is None else f"{val:.6g} Q.{q}"
        mac = "acn_mac_hi" if i == len(h.ops) - 1 else "acn_mac"  # the last one gives the high word
        x = f"({x} >> {k})" if k or _EXPLICIT_SHIFTS.get() else x
        acc = f"{mac}({acc}, {x}, {_c_int(ki, 32)} /* {cm} */)"
    return f"{acc} /* Q.{h.F} -> Q.{h.ft}, high word */"


def _entry(how, P: str) -> str:
    """C of one planned predict entry (codegen.plan_cov.CovSums.predict)."""
    shape, x0, s = how
    if shape == "hadd":  # x0 + rest: one saturating 32-bit add, the rest fits int32 for any inputs
        return f"acn_add_sat32({x0}, {_hsum(s)}, &s->overflow)"
    if shape == "addsat":
        return f"acn_add_sat32({x0}, (int32_t){_acc(s, P)}, &s->overflow)"
    if shape == "sat":
        return f"acn_sat32({_acc(s, P)}, &s->overflow)"
    if shape == "h":  # x - (1 - phi) x fits int32 for every int32 x (see _predict_cov)
        return f"(int32_t)((int64_t){x0} + {_hsum(s)})"
    if shape == "free":
        return f"(int32_t)((int64_t){x0} + {_hsum(s)})"
    return f"(int32_t){_acc(s, P)}"


def _predict_cov(sums: CovSums, p: AxisPlan, P: str) -> list[str]:
    """The predict of the carried block, as planned (codegen.plan_cov.cov_sums).

    x - (1 - phi) x fits int32 for every int32 x: 0 < 1 - phi < 1, the product enters with the sign
    opposite to x, and neither its floor nor the rounding offset (below one LSB) can push past x."""
    t = {n: _entry(how, P) for n, how in sums.predict.items()}
    ce_shape = sums.predict["ce"][0]
    if ce_shape in ("free", "hadd"):
        ce = f"        s->ce = {t['ce']};" + (
            " /* fits int32 for any c_e, P_ae: checked at the corners */" if "ce" in p.sat_free else ""
        )
    elif ce_shape == "acc":
        ce = f"        s->ce = {t['ce']}; /* fits int32 for any c_e, P_ae: ranges._predict_sat_free */"
    else:
        ce = f"        s->ce = {t['ce']};"
    return [
        "        /* P = F P F' + Q on the carried block (c = P H' carried directly in fine formats);",
        "         * every right-hand side reads the old values; each sum is rounded once */",
        "        int32_t tr, tv;",
        "        uint32_t dz = acn_rbit(s->k >> 1); /* rounding offsets: the sample count, bit-reversed */",
        "        /* tr = P_re + P_ve + Ts^2/2 P_ae; P_re' = phi tr */",
        f"        tr = {t['tr']};",
        "        /* tv = P_ve + Ts^2 P_ae; P_ve' = phi tv */",
        f"        tv = {t['tv']};",
        "        /* c_r' = c_r + c_v + Ts^2/2 c_a + Q_ra - (1 - phi) tr */",
        f"        s->cr = {t['cr']};",
        "        /* c_v' = c_v + Ts^2 c_a + Ts Q_ua - (1 - phi) tv */",
        f"        s->cv = {t['cv']};",
        f"        s->Pre = {t['Pre']};",
        f"        s->Pve = {t['Pve']};",
        "        /* c_a' = c_a + Q_aa - (1 - phi) P_ae */",
        f"        s->ca = {t['ca']};",
        "        /* c_e' = phi^2 c_e + phi (1 - phi) P_ae + Q_ee */",
        ce,
        "        /* P_ae' = phi P_ae = P_ae - (1 - phi) P_ae */",
        f"        s->Pae = {t['Pae']};",
    ]


def _gains_cov(sums: CovSums, p: AxisPlan, P: str) -> list[str]:
    """Body of T_pupdate(s, y), the measurement update: S = c_a + c_e + R, one reciprocal, w = y / S;
    every state adds c_i w = K_i y (r and v = Ts u their K y part only; the core adds the rest of
    their step), so no gain is rounded on its own; then P = P - c c' / S, which for the carried
    c = P H' is c_i -> c_i (1 - kappa) with kappa = (S - R) / S, and P_ie -= c_i K_e with K_e = c_e / S
    (all from the prior block). The posterior entries are not saturated: the update only contracts
    the block (c_i -> c_i R / S, and the cross terms stay within the diagonal terms, which only
    shrink)."""
    fca, fce, fKe = p.f("ca"), p.f("ce"), p.f("Ke")
    cf = sums.fracs
    nmax, fx = cf["nmax"], cf["x"]
    d = fce - fca
    Rn = "RF" if p.vars["S"] is p.vars.get("S_f") else "R"  # R in the format of S: fine or coarse
    # c_e in c_a's format, rounded (ties up) in 32 bits: floor((floor(c_e / 2^(d-1)) + 1) / 2)
    ce_a = f"(((ce >> {d - 1}) + 1) >> 1) /* Q.{fce} -> Q.{fca}, round */" if d > 0 else ""
    fy, fw, fr, fv, fe = p.f("y"), p.f("w"), p.f("r"), p.f("v"), p.f("e")
    pr = cf["prod"]
    # w's shift, and kappa's, K_e's and a's, are checked in range by the planner
    L = [
        "    int32_t cr = s->cr, cv = s->cv, ca = s->ca, ce = s->ce, S, xs, w, kap, Ke;",
        "    uint32_t x;",
        "    int n;",
        "    /* S = H P H' + R = c_a + c_e + R (>= R by construction) */",
        # one saturating 32-bit add when c_e aligned plus R fits int32 for any c_e (see _acc_sat)
        f"    S = acn_add_sat32(ca, {ce_a} + {P}_{Rn}, &s->overflow);"
        if sums.s_fits
        else f"    S = acn_sat32((int64_t)ca + {_shift('(int64_t)ce', fce, fca)} + {P}_{Rn}, &s->overflow);",
        f"    if (S < {P}_{Rn}) {{",
        f"        S = {P}_{Rn};",
        "    }",
        f"    /* 1/S: one reciprocal, 1/S = x 2^(n-62) with n = clz(S) in 1..{nmax}; x >> ({nmax} - n)",
        f"     * puts it at 1/S = x 2^({nmax - 62}) for every S (dropping at most {nmax} of its 30 bits):",
        f"     * xs = 1/S in Q.{fx} */",
        "    x = acn_recip_t((uint32_t)S, &n);",
        f"    x >>= {nmax} - n;",
        "    xs = (int32_t)(x >> 1); /* below 2^31: each product is one signed 32x32 multiply */",
        "    /* w = y / S (|w| <= max|y| / R: fits, no saturation) */",
        f"    w = {_mul_round32('y', 'xs', fy + fx, fw)}; /* Q.{fy} x Q.{fx} -> {p.vars['w'].fmt} */",
        "    /* x = x + K y = x + c w (K = c / S), c the prior block: r and v = Ts u take K_r y, K_v y here,",
        "     * the rest of their step in the core */",
        f"    s->r += {_sh('acn_mul(cr, w)', pr['r'] - fr, 'Q.{} -> Q.{}'.format(pr['r'], fr))};",
        f"    s->v += {_sh('acn_mul(cv, w)', pr['v'] - fv, 'Q.{} -> Q.{}'.format(pr['v'], fv))};",
        f"    s->a = (int32_t)((uint32_t)s->a + (uint32_t){_mul_round32('ca', 'w', pr['a'], fy)});",
        f"    s->e = acn_mac(s->e, ce, w); /* Q.{fe}, exact */"
        if pr["e"] == fe
        # c_e in a format finer than the one whose product with w lands in eps's (its fine format,
        # codegen.ranges._plan_fine): floored to that one, which is no finer than its coarse format,
        # so eps takes c_e to within one LSB of its coarse format and still in one SMLAL; the carried c_e, S and
        # K_e keep the fine format
        else f"    s->e = acn_mac(s->e, ce >> {pr['e'] - fe}, w); /* c_e Q.{p.f('ce')} -> Q.{fe - fw}, floor;"
        f" Q.{fe}, exact */"
        if pr["e"] > fe and fe - fw >= p.vars.get("ce_c", p.vars["ce"]).fmt.frac
        else f"    s->e += {_sh('acn_mul(ce, w)', pr['e'] - fe, 'Q.{} -> Q.{}'.format(pr['e'], fe))};",
        "    /* P = P - c c' / S: c_i -= c_i kappa with kappa = (S - R) / S in [0, 1), Q0.31;",
        "     * P_ie -= c_i K_e with K_e = c_e / S */",
        f"    kap = {_mul_round32(f'S - {P}_{Rn}', 'xs', fca + fx, 31)}; /* kappa, Q0.31 */",
        # K_e without saturation when the planner found it fits int32 for any c_e (codegen.plan_cov)
        f"    Ke = {_mul_round32('ce', 'xs', fce + fx, fKe)}; /* K_e {p.vars['Ke'].fmt}: fits for any c_e */"
        if sums.ke_free
        else f"    Ke = acn_sat32(ACN_RSHR(acn_mul(ce, xs), {fce + fx - fKe}), &s->overflow);"
        f" /* Q.{fce + fx} -> {p.vars['Ke'].fmt}, round */",
    ]
    # the posterior entries in 32-bit arithmetic: the same low word as the int64 difference cast back
    for dst, ci in (("Pre", "cr"), ("Pve", "cv"), ("Pae", "ca")):
        dec = _mul_round32(ci, "Ke", p.f(ci) + fKe, p.f(dst))
        L.append(f"    s->{dst} = (int32_t)((uint32_t)s->{dst} - (uint32_t){dec});")
    for ci in ("cr", "cv", "ca", "ce"):
        dec = _mul_round32(ci, "kap", p.f(ci) + 31, p.f(ci))
        L.append(f"    s->{ci} = (int32_t)((uint32_t){ci} - (uint32_t){dec});")
    return L


def _core_cov(p: AxisPlan, P: str, T: str) -> list[str]:
    """Body of T_core for the covariance form: as _core_fixed, with the update of _gains_cov inline
    (the prior block is read once into registers; the predict of the block stays a function of its own).

    The common path: a valid sample with c_r, c_v, c_a, c_e in their fine formats (bit 0 of k set,
    codegen.ranges._plan_fine); a skip, or a block still in its coarse formats, goes to T_core_c."""
    L = [
        "    int32_t a;",
        "    int64_t e, v0, r, v;",
        "    if (!valid || __builtin_expect((int32_t)(s->k << 31) >= 0, 0)) { /* a skip, or coarse formats */",
        f"        {T}_core_c(s, z, valid);",
        "        return;",
        "    }",
        "    a = s->a;",
        "    e = s->e;",
        "    v0 = s->v;",
    ]
    return L + _cov_step(p, P, T, "", "    s->k += 2u; /* the sample count, in bits 1..31 */")


def _cov_step(p: AxisPlan, P: str, T: str, sfx: str, tail: str, back: list[str] | None = None) -> list[str]:
    """One step of the covariance form after its states are loaded: eps decay and the block's predict
    (T_ppredict{sfx}), the update (T_pupdate{sfx}, then ``back``), the steps of r and v, ``tail``."""
    fr, fv, fe, fy = p.f("r"), p.f("v"), p.f("e"), p.f("y")
    fo = p.consts["OMP"][1].frac
    eh = _hi_round("e")
    fH2, fT2 = p.consts["H2"][1].frac, p.consts["T2"][1].frac
    decay = (
        f"e -= {_sh(f'acn_mul({P}_OMP, {eh} - {P}_EBAR)', fo - 32, f'Q.{fo + fy} -> Q.{fe}')};"
        if fo != 32
        else f"e = acn_mac(e, -{P}_OMP, {eh} - {P}_EBAR); /* Q.{fo + fy}, exact: one SMLAL */"
    )
    com = "/* eps = phi eps + b = eps - (1 - phi) (eps - eps_bar), eps by its rounded high word */"
    if sfx:  # the coarse step: the first sample has no predict
        L = ["    if (k > 1u) {", f"        {com}", f"        {decay}", f"        {T}_ppredict{sfx}(s);", "    }"]
    else:
        L = [f"    {com}", f"    {decay}", f"    {T}_ppredict(s);"]
    L += [
        "    s->e = e;",
        "    if (valid) {",
        "        /* y = z - H x = z - a - eps; K = P H' / S, x = x + K y and P = P - K H P */",
        f"        {T}_pupdate{sfx}(s, z - a - {_hi_round('e')});",
        *(back or []),
        "    }",
        "    /* r += Ts u + Ts^2/2 a,  u += Ts a (K_r y and K_v y are in already); u and a are the previous",
        "     * posteriors, and at k = 0 both increments are zero (x0 has r = u = a = 0): no test of k */",
        f"    r = s->r + {_sh('v0', fv - fr, f'Q.{fv} -> Q.{fr}')}"
        f" + {_sh(f'acn_wmul({P}_H2, a)', fH2 + fy - fr, f'Q.{fH2 + fy} -> Q.{fr}')};",
        f"    v = s->v + {_sh(f'acn_wmul({P}_T2, a)', fT2 + fy - fv, f'Q.{fT2 + fy} -> Q.{fv}')};",
        f"    s->r = acn_limit(r, {P}_RHI, &s->overflow);",
        f"    s->v = acn_limit(v, {P}_VHI, &s->overflow);",
        tail,
    ]
    return L


def _core_cov_coarse(c: AxisCode, P: str, T: str) -> list[str]:
    """Body of T_core_c (out of line): a skipped sample, or a sample while c_r, c_v, c_a, c_e are in their
    coarse formats (the ones that hold them through a gap). A skip first moves a fine block to the
    coarse formats (rounded); after an update whose c_r, c_v, c_a, c_e are all within the switch levels
    p.theta (codegen.ranges._plan_fine) they move to the fine formats (exact: a left shift that fits)."""
    p = c.p
    pf = c.cov[0].view
    to_c, to_f, test = [], [], []
    for nm in FINE:
        dd = pf.f(nm) - p.f(nm)
        fc, ff = p.vars[nm].fmt, pf.vars[nm].fmt
        if dd > 0:
            to_c.append(f"        s->{nm} = (int32_t)ACN_RSHR((int64_t)s->{nm}, {dd}); /* {ff} -> {fc}, round */")
            to_f.append(f"            s->{nm} *= INT32_C(1) << {dd}; /* {fc} -> {ff}, exact */")
        th = c.switch[nm]
        # |c| <= th as one unsigned compare; th 2^dd fits the fine format (it holds GUARD theta)
        test.append(f"(uint32_t)s->{nm} + UINT32_C({th}) <= UINT32_C({2 * th})")
    back = [
        "        /* back to the fine formats once c_r, c_v, c_a, c_e are within their switch levels */",
        "        if (" + " && ".join(test) + ") {",
        *to_f,
        "            k |= 1u;",
        "        }",
    ]
    L = [
        "    int32_t a = s->a;",
        "    int64_t e = s->e, v0 = s->v, r, v;",
        "    uint32_t k = s->k;",
        "    if (k & 1u) { /* a skip with the block in its fine formats: to the coarse ones */",
        *to_c,
        "        k ^= 1u;",
        "    }",
    ]
    return L + _cov_step(p, P, T, "_c", "    s->k = k + 2u; /* the sample count, in bits 1..31 */", back)


def _gs_load(P: str, T: str, predict: str, follow: bool) -> list[str]:
    """The gain schedule's step up to its predict of eps: declarations, the gains and eb loaded."""
    L = [
        "    int32_t y, a = s->a;",
        "    int64_t e, p, q, r, v;",
        "    uint32_t kr, kv, klo, khi; /* K_r, K_v and K_e's accumulator, each pair in one LDRD */",
        "    uint32_t lo, hi; /* an int64 state's two words, in one LDRD */",
    ]
    if follow:
        L += [
            "    int32_t Kr, Kv, Ka, Ke;",
            "    uint32_t k = s->k;",
            f"    if (__builtin_expect(k == {P}_FOLLOWING, 0)) {{",
            "        /* the count reached 2^31 on the schedule: it restarts at 2^30, past the schedule's end */",
            f"        k = {P}_KWRAP;",
            "        s->k = k;",
            "    }",
            f"    k &= ~{P}_FOLLOWING;",
        ]
    L += [
        f"    ACN_LD2(kr, kv, s, {T}_t, Kr, Kv);",
        f"    ACN_LD64(lo, hi, s, {T}_t, eb);",
        "    e = (int64_t)(((uint64_t)hi << 32) | lo);",
    ]
    if follow:
        L += [f"    ACN_LD2(klo, khi, s, {T}_t, Ke_lo, Ke);"]
        L += ["    if (k > 0) {", f"        {predict}", "    }"]
    else:
        L += [f"    {predict}"]
    return L


def _gs_tail(P: str, T: str, follow: bool) -> list[str]:
    """The gain schedule's step after r and v: the clamps, the count, and the next sample's gains."""
    L = [
        f"    s->r = acn_limit(r, {P}_RHI, &s->overflow);",
        f"    v = acn_limit(v, {P}_VHI, &s->overflow);",
        f"    ACN_ST64(v, s, {T}_t, v);",
        "    ++k;",
    ]
    if follow:
        L += [f"    s->k = (s->k & {P}_FOLLOWING) | k; /* the flag as the deviation left it */"]
    else:
        L += ["    s->k = k;"]
    if not follow:  # K_e's two words only now: kept from the top they crowd the update's registers
        L += [f"    ACN_LD2(klo, khi, s, {T}_t, Ke_lo, Ke);"]
    L += [f"    {T}_gains(s, k, kr, kv, klo, khi);"]
    return L


def _core_fixed(c: AxisCode, P: str, T: str, follow: bool = False) -> list[str]:
    """Body of the gain schedule's T_core (follow False) or T_core_dev (follow True): predict and update
    merged, every state read and written once.

    T_core(s, zb, k) is the common sample: valid, k > 0 and on the schedule; zb = z - eps_bar. T_core_dev
    (s, z, valid) is any other: the first sample, a skipped one, or one while following a skip
    (codegen.follow), out of line.

    Contract (formats from :mod:`codegen.ranges`): z, y, a in Q.fy (int32); eps carried as eb = eps -
    eps_bar + 1/2 LSB of its high word (int64 in Q.(fy+32)): the high word of eb is eps - eps_bar
    rounded, so the predict needs neither the rounding nor eps_bar, and y takes eps_bar with z; r and
    v = Ts u int64 in one format Q.fr; K_a, K_e int32 each with its own scaling, K_r (K_v) in the format
    of Ts^2/2 (Ts^2), or Ts^2/2 in v's product format Q.(fv - fy) (codegen.ranges): then w = v + Ts^2/2 a
    starts both increments, r's shifted to K_r y's format, v's with (Ts^2 - Ts^2/2) a, the same integer
    sum as Ts^2 a. Products are 32x32 -> 64 (one SMULL or SMLAL); every shift is a floor except the
    one that makes a (round to nearest). r and v are clamped once per step on their high words; nothing
    else can overflow over the declared ranges.
    """
    p, m = c.p, c.merge
    if p.form == "covariance":
        return _core_cov(p, P, T)
    fr, fv, fy, fe = p.f("r"), p.f("v"), p.f("y"), p.f("e")
    fK = {n: p.f("K" + n) for n in "rvae"}
    fo = p.consts["OMP"][1].frac
    sa = fK["a"]  # Q.(fKa + fy) -> Q.fy
    ft = {"r": fr, "v": fv, "e": fe}
    conv = {n: f"Q.{fK[n] + fy} -> Q.{ft[n]}" for n in "rve"}
    # Ts^2/2 a and Ts^2 a: in the accumulator of K_r y (K_v y) when they share its format, else shifted apart
    post = {}  # the planner's choice of sums (codegen.plan.Merge): Ts^2/2 a, Ts^2 a shifted in apart or not
    for n, cn, apart in (("r", "H2", m.h2_apart), ("v", "T2", m.t2_apart)):
        fc = p.consts[cn][1].frac
        post[n] = " + " + _sh(f"(int64_t){P}_{cn} * a", fc + fy - ft[n], f"Q.{fc + fy} -> Q.{ft[n]}") if apart else ""
    a_in_v, merge_v, onto_v, fp = m.a_in_v, m.merge_v, m.onto_v, m.fp
    # the constant of a in v's increment: Ts^2, or Ts^2 - Ts^2/2 (the same integer sum) after w
    cq = f"({P}_T2 - {P}_H2)" if a_in_v else f"{P}_T2"
    eh = "(int32_t)(e >> 32)"  # eps - eps_bar, rounded: the high word of eb
    predict = (
        f"e = acn_mac(e, -{P}_OMP, {eh}); /* eps = phi eps + b = eps - (1 - phi) (eps - eps_bar): Q.{fo + fy} */"
        if fo == 32
        else f"e -= {_sh(f'(int64_t){P}_OMP * {eh}', fo - 32, f'Q.{fo + fy} -> Q.{fe}')};"
        " /* eps = phi eps + b = eps - (1 - phi) (eps - eps_bar) */"
    )
    L = _gs_load(P, T, predict, follow)
    L += [
        "    /* r += Ts u + Ts^2/2 a (+ K_r y),  u += Ts a (+ K_v y); a is the previous posterior, and at",
        "     * k = 0 both increments are zero (x0 has r = u = a = 0), so no test of k is needed */",
    ]
    if merge_v or onto_v:
        L += [f"    ACN_LD64(lo, hi, s, {T}_t, v);"]
        L += [] if a_in_v and not follow else ["    v = (int64_t)(((uint64_t)hi << 32) | lo);"]
    # (accumulator's start, whether Ts^2/2 a (Ts^2 a) goes into it)
    if a_in_v and not follow:  # w, its shift and K_r y in one asm (the update below): no register copies
        p0 = ("", False)
    else:
        if a_in_v:
            L += [f"    v = acn_mac(v, {P}_H2, a); /* w = v + Ts^2/2 a, Q.{fv}: both increments start from it */"]
        if merge_v:
            p0 = (_sh("v", fv - fp, f"Q.{fv} -> Q.{fp}"), not post["r"] and not a_in_v)
        else:
            p0 = ("0", False) if post["r"] else ("0", True)
    q0 = ("v", True) if onto_v else ("0", not post["v"])
    macs = {}
    for n, (start, with_a), cn, kn in (("p", p0, f"{P}_H2", "Kr"), ("q", q0, cq, "Kv")):
        what = {"p": "r's increment", "q": "v + Ts^2 a + K_v y" if onto_v else "v's increment"}[n]
        what += f", Q.{fp if n == 'p' else fK['v'] + fy}"
        if follow:  # the Ts^2 a term before the update (a skipped sample has only it)
            L += [f"    {n} = acn_mac({start}, {cn}, a);" if with_a else f"    {n} = {start};"]
            macs[n] = f"acn_mac({n}, {kn}, y); /* {what} */"
        else:  # both products in one asm: no register copies between them
            mac = f"acn_mac2({start}, {cn}, a, {kn}, y)" if with_a else f"acn_mac({start}, {kn}, y)"
            macs[n] = f"{mac}; /* {what} */"
    upd = [
        "    /* y = z - H x = z - a - eps, eps rounded = high word of eb + eps_bar: zb = z - eps_bar */",
        f"    y = (int32_t)((uint32_t)zb - (uint32_t)a - (uint32_t){eh});",
        "    /* x = x + K y */",
        f"    e += {_sh('(int64_t)Ke * y', fK['e'] - 32, conv['e'])};",
        *(
            [f"    p = {macs['p']}"]
            if p0[0]
            else [
                "    {",
                "        uint32_t plo, phi;",
                f"        /* w = v + Ts^2/2 a in Q.{fv}; p = (w >> {fv - fp}: Q.{fv} -> Q.{fp}, floor) + K_r y */",
                f"        ACN_MAC_SHR_MAC(lo, hi, {P}_H2, a, {fv - fp}, Kr, y, plo, phi);",
                f"        p = (int64_t)(((uint64_t)phi << 32) | plo); /* r's increment, Q.{fp} */",
                "        v = (int64_t)(((uint64_t)hi << 32) | lo);",
                "    }",
            ]
        ),
        f"    q = {macs['q']}",
        f"    s->a = a + (int32_t)ACN_RSHR(acn_mul(Ka, y), {sa}); /* Q.{fK['a'] + fy} -> Q.{fy}, round */"
        if not 1 <= sa <= 32
        else f"    s->a = acn_add_round(a, acn_mul(Ka, y), {sa}); /* a + K_a y: Q.{fK['a'] + fy} -> Q.{fy}, round */",
    ]
    if follow:
        L += [
            "    K[0] = (int32_t)kr;",
            "    K[1] = (int32_t)kv;",
            "    K[2] = ACN_ROM_I32(&s->seg->ka); /* K_a: held over the row */",
            "    K[3] = (int32_t)khi;",
            "    if (valid) {",
            f"        int32_t zb = (int32_t)((uint32_t)z - (uint32_t){P}_EBAR);",
            f"        if (s->k & {P}_FOLLOWING) {{",
            "            /* after a skip: the schedule's gains plus the carried deviation (codegen.follow) */",
            f"            {T}_follow(s, true, K);",
            "        }",
            "        Kr = K[0];",
            "        Kv = K[1];",
            "        Ka = K[2];",
            "        Ke = K[3];",
        ]
        L += ["    " + ln for ln in upd]
        L += [
            "    } else {",
            "        /* skipped: the gains of the next samples leave the schedule (codegen.follow) */",
            f"        {T}_follow(s, false, K);",
            "    }",
        ]
        L[1:1] = ["    int32_t K[4];"]
    else:
        L += [
            "    {",
            "        int32_t Kr = (int32_t)kr, Kv = (int32_t)kv, Ka = ACN_ROM_I32(&s->seg->ka), Ke = s->Ke;",
        ]
        L += ["    " + ln for ln in upd]
        L += ["    }"]
    L += [
        "    s->eb = e;",
    ]
    if merge_v:
        L += [
            f"    ACN_LD64(lo, hi, s, {T}_t, r);",
            f"    r = (int64_t)(((uint64_t)hi << 32) | lo) + {_sh('p', fp - fr, f'Q.{fp} -> Q.{fr}')}{post['r']};",
        ]
    else:
        if not onto_v:
            L += [f"    ACN_LD64(lo, hi, s, {T}_t, v);", "    v = (int64_t)(((uint64_t)hi << 32) | lo);"]
        L += [
            f"    ACN_LD64(lo, hi, s, {T}_t, r);",
            f"    r = (int64_t)(((uint64_t)hi << 32) | lo) + {_sh('v', fv - fr, f'Q.{fv} -> Q.{fr}')}"
            f" + {_sh('p', fK['r'] + fy - fr, conv['r'])}{post['r']};",
        ]
    L += ["    v = q;" if onto_v else f"    v += {_sh('q', fK['v'] + fy - fv, conv['v'])}{post['v']};"]
    return L + _gs_tail(P, T, follow)


RUNTIME_HEADER = "acn_runtime.h"  # codegen/csrc: the runtime every fixed-point filter carries


@functools.cache
def runtime_text() -> str:
    """The C runtime (acn_runtime.h, package data) between its clang-format markers: copied into every
    generated .c, so that a generated filter needs no other file."""
    text = (package_dir("accelnav.codegen") / "csrc" / RUNTIME_HEADER).read_text()
    begin, end = "/* clang-format off */\n", "/* clang-format on */\n"
    return text[text.index(begin) + len(begin) : text.index(end)]


def recip_helpers() -> str:
    """C of acn_recip_t, the covariance form's reciprocal: a table start (relative error below 2^-8)
    and two Newton-Raphson steps (2^-16, then below 2^-28 with the arithmetic's rounding) instead of
    acn_recip's linear start and three steps: the same contract, fewer instructions."""
    nb = RECIP_TABLE_BITS
    tab = recip_table(nb)
    rows = [", ".join(str(x) for x in tab[j : j + 12]) for j in range(0, len(tab), 12)]
    body = ",\n    ".join(rows)
    return f"""
/* 1/D for D in [1/2, 1) in Q2.30 >> 15, at the middle of each of 2^{nb} equal intervals */
static const uint16_t acn_rtab[{2**nb}] ACN_ROM = {{
    {body}}};

/* As acn_recip (1/d = x 2^(n-62), x in Q2.30, n = clz(d), d > 0, relative 2^-28): the start from
 * acn_rtab (relative error below 2^-8), then two Newton-Raphson steps. */
static inline uint32_t acn_recip_t(uint32_t d, int *n)
{{
    uint32_t dn, x;
    *n = acn_clz32(d);
    dn = d << *n;                                                           /* D, Q0.32 */
    x = (uint32_t)ACN_ROM_U16(&acn_rtab[(dn >> {31 - nb}) & {2**nb - 1}u]) << 15; /* Q2.30, from flash on AVR */
    ACN_NR(dn, x);
    ACN_NR(dn, x);
    return x;
}}
"""


_schedule_for = schedule_for  # its name before codegen.plan: tests and bench/ import it from here


def _gs_defines(c: AxisCode, P: str) -> list[str]:
    """Gain schedule: the flag of k, its restart value and eps's offset from the state eb."""
    fe, eoff = c.p.f("e"), c.eoff
    return [
        f"#define {P}_FOLLOWING UINT32_C(0x80000000) /* bit of k: following a skip (codegen.follow) */",
        f"#define {P}_KWRAP UINT32_C(0x40000000) /* k past 2^31 - 1 samples restarts here, beyond the schedule */",
        f"#define {P}_EOFF {_c_int(eoff, 64)} /* eps = eb + EOFF: eps_bar 2^32 - 2^31, Q.{fe} */",
    ]


def _gs_entries(c: AxisCode, P: str, T: str, params: str, args: str) -> list[str]:
    """Gain schedule: T_core (the common sample, inlined), T_core_dev (any other, out of line), and the
    entry points update, skip and step. The common path tests one word: k, whose sign bit says
    "following a skip" and whose zero says "first sample"; both go out of line."""
    p = c.p
    fz = p.f("z")
    src = [
        "/* The common sample: valid, not the first (k > 0), on the schedule. zb = z - eps_bar, z [m/s^2]",
        f" * {p.vars['z'].fmt}. Inlined into update and step. */",
        f"ACN_INLINE void {T}_core({T}_t *s, int32_t zb, uint32_t k)",
        "{",
    ]
    src += _core_fixed(c, P, T)
    src += ["}", ""]
    src += [
        "/* Any other sample (the first, a skipped one, one while following a skip, codegen.follow):",
        " * the core with the deviation carried. Rare: out of line. */",
        f"static __attribute__((noinline)) void {T}_core_dev({T}_t *s, int32_t z, bool valid)",
        "{",
    ]
    src += _core_fixed(c, P, T, follow=True)
    src += ["}", ""]
    src += [
        f"void {T}_update({T}_t *s, int32_t z)",
        "{",
        "    uint32_t k = s->k;",
        "    if (__builtin_expect((int32_t)k <= 0, 0)) { /* the first sample, or following a skip */",
        f"        {T}_core_dev(s, z, true);",
        "    } else {",
        f"        {T}_core(s, (int32_t)((uint32_t)z - (uint32_t){P}_EBAR), k);",
        "    }",
        "}",
        "",
        "/* A sample that must be skipped (rail-clipped, missing capture): predict only. */",
        f"void {T}_skip({T}_t *s)",
        "{",
        f"    {T}_core_dev(s, 0, false);",
        "}",
        "",
        "/* T_step out of the common path: the first sample, or following a skip. */",
        f"static __attribute__((noinline)) bool {T}_step_dev({T}_t *s, {params})",
        "{",
        "    int32_t z = 0;",
        f"    bool valid = {T}_convert({args}, &z);",
        f"    {T}_core_dev(s, z, valid);",
        "    return valid;",
        "}",
        "",
        "/* Convert the raw input and run one step; returns false when the sample was skipped. */",
        f"bool {T}_step({T}_t *s, {params})",
        "{",
        "    int32_t z = 0;",
        "    uint32_t k = s->k;",
        "    if (__builtin_expect((int32_t)k <= 0, 0)) { /* the first sample, or following a skip */",
        f"        return {T}_step_dev(s, {args});",
        "    }",
        f"    if (__builtin_expect(!{T}_convert({args}, &z), 0)) {{",
        f"        {T}_skip(s); /* rare: out of line */",
        "        return false;",
        "    }",
        f"    /* z - eps_bar in Q.{fz}: the conversion's offset and eps_bar fold into one constant */",
        f"    {T}_core(s, (int32_t)((uint32_t)z - (uint32_t){P}_EBAR), k);",
        "    return true;",
        "}",
        "",
    ]
    return src


def _axis_decls(p: AxisPlan, T: str, fields, params: str) -> tuple[list[str], list[str], list[str]]:
    """The state struct, the output struct and the prototypes of one axis: (struct, out_struct, protos)."""
    struct = ["typedef struct {"] + [f"    {t}{'' if t.endswith('*') else ' '}{n}; /* {c} */" for t, n, c in fields]
    struct += [f"}} {T}_t;"]
    out_struct = [
        "typedef struct {",
        f"    int64_t r; /* [m] {p.vars['r'].fmt} */",
        f"    int64_t u; /* [m/s] {p.vars['u_out'].fmt} */",
        f"    int32_t a; /* [m/s^2] {p.vars['a'].fmt} */",
        f"    int64_t e; /* [m/s^2] {p.vars['e'].fmt} */",
        f"}} {T}_out_t;",
    ]
    protos = [
        f"void {T}_init({T}_t *s);",
        f"bool {T}_convert({params}, int32_t *z);",
        f"bool {T}_step({T}_t *s, {params});",
        f"void {T}_skip({T}_t *s);",
        f"void {T}_update({T}_t *s, int32_t z);",
        f"void {T}_read(const {T}_t *s, {T}_out_t *o);",
        f"void {T}_save(const {T}_t *s, uint8_t *out);",
        f"bool {T}_load({T}_t *s, const uint8_t *in);",
    ]
    return struct, out_struct, protos


def _gs_table(c: AxisCode, P: str, T: str) -> list[str]:
    """The gain schedule's table of rows (in flash on AVR) and its size."""
    sched = c.sched
    src = [f"#define {P}_NSEG {sched.n_segments}"]
    src.append("/* segment j: K_a holds its ka; after every sample of it K_r, K_v and K_e add their slopes;")
    src.append(" * it ends when end[j] samples are done. The last row (zero slopes, the last ka, end 0:")
    src.append(" * never reached) holds the gains. */")
    src.append(f"struct {T}_seg_s {{")
    src.append("    int32_t dr, dv; /* per-sample slopes of K_r, K_v */")
    src.append("    uint32_t de_lo; /* K_e's per-sample slope: int64, low word */")
    src.append("    int32_t de_hi; /* ... and high word */")
    src.append("    int32_t ka; /* K_a over the segment */")
    src.append("    uint32_t end; /* samples done when the segment ends */")
    src.append("};")
    src.append(f"typedef struct {T}_seg_s {T}_seg_t;")
    src.append(
        "/* K_r, K_v, K_a, K_e in LSB of ("
        + ", ".join(str(f) for f in sched.formats)
        + f"; K_e's is Q.{sched.formats[3].frac + 32}) */"
    )
    src.append("/* in flash on AVR (ACN_ROM): kilobytes the 2 KiB of an ATmega328P's RAM could not hold */")
    src.append(f"static const {T}_seg_t {T}_seg[{P}_NSEG + 1] ACN_ROM = {{")
    end = 0
    for L, sl in zip(sched.lengths, sched.slopes, strict=True):
        end += L
        e64 = sl[3] & 0xFFFFFFFFFFFFFFFF
        src.append(
            "    {"
            + ", ".join(_c_int(x, 32) for x in sl[:2])
            + f", UINT32_C({e64 & 0xFFFFFFFF}), {_c_int((e64 >> 32) - ((e64 >> 63) << 32), 32)}"
            + f", {_c_int(sl[2], 32)}, {end}u}},"
            + f" /* K_e slope {sl[3]} */"
        )
    last = sched.slopes[-1] if sched.n_segments else (0, 0, sched.start[2], 0)
    src.append(f"    {{0, 0, 0u, 0, {_c_int(last[2], 32)}, 0u}},")
    src.append("};")
    src.append("")
    return src


def _init_c(c: AxisCode, T: str) -> list[str]:
    """T_init: the initial state in its formats."""
    x0 = c.x0
    src = [
        f"void {T}_init({T}_t *s)",
        "{",
        f"    s->r = {_c_int(x0[0], 64)};",
        f"    s->v = {_c_int(x0[1], 64)};",
        f"    s->a = {_c_int(x0[2], 32)};",
    ]
    if c.p.form == "covariance":
        src.append(f"    s->e = {_c_int(x0[3], 64)};")
        for nm, (val, q) in c.cov0.items():
            src.append(f"    s->{nm} = {_c_int(q, 32)}; /* {val:.17g} */")
    else:
        sched = c.sched
        for i, nm in enumerate("rv"):
            src.append(f"    s->K{nm} = {_c_int(sched.start[i], 32)};")
        ke0 = sched.start[3]
        src.append(f"    s->Ke_lo = UINT32_C({ke0 & 0xFFFFFFFF});")
        src.append(f"    s->Ke = {_c_int(ke0 >> 32, 32)};")
        src.append(f"    s->seg = &{T}_seg[0];")
        src.append(f"    s->eb = {_c_int(x0[3] - c.eoff, 64)}; /* eps0 - EOFF */")
        src.append("    s->Dcr = s->DPre = s->Dcv = s->DPve = s->Dca = s->DPae = s->Dce = 0;")
        src.append("    s->z = 0;")
    return src + ["    s->k = 0;", "    s->overflow = 0;", "}", ""]


def _gs_gains_c(c: AxisCode, P: str, T: str) -> list[str]:
    """T_gains (one step along the schedule) and T_follow (codegen.follow, planned and checked)."""
    from .follow import emit_follow

    return [
        "/* The gains of the next sample: one step along the schedule; k = samples done, kr, kv, klo, khi",
        " * the current K_r, K_v and K_e's accumulator words (already loaded by the core). */",
        f"ACN_INLINE void {T}_gains({T}_t *s, uint32_t k, uint32_t kr, uint32_t kv, uint32_t klo, uint32_t khi)",
        "{",
        f"    const {T}_seg_t *d = s->seg;",
        "    uint32_t dr, dv, dlo, dhi;",
        "    uint64_t ke;",
        f"    ACN_SEG2(dr, dv, d, {T}_seg_t, dr, dv); /* the row is in flash on AVR */",
        f"    ACN_SEG2(dlo, dhi, d, {T}_seg_t, de_lo, de_hi);",
        "    ke = (((uint64_t)khi << 32) | klo) + (((uint64_t)dhi << 32) | dlo); /* wraps like int64 */",
        f"    ACN_ST2(kr + dr, kv + dv, s, {T}_t, Kr, Kv); /* wraps like int32 (never does: a gain) */",
        f"    ACN_ST2((uint32_t)ke, (uint32_t)(ke >> 32), s, {T}_t, Ke_lo, Ke);",
        f"    if (k == ACN_ROM_U32(&d->end) && d != &{T}_seg[{P}_NSEG]) {{",
        "        s->seg = ++d; /* K_a is read from the row */",
        "    }",
        "}",
        "",
    ] + emit_follow(c.follow, P, T)


def _cov_step_fns(c: AxisCode, P: str, T: str) -> list[str]:
    """The covariance form's step: its block's predict and update (fine and coarse formats), T_core_c
    and T_core (what axes share on AVR, codegen.share)."""
    p = c.p
    src = []
    # the predict of the covariance block in a function of its own: its registers do not crowd the
    # states'; twice: c_r, c_v, c_a, c_e in their fine formats (the common path) and in their coarse ones
    for sfx, sums in (("", c.cov[0]), ("_c", c.cov[1])):
        q = sums.view
        src += [f"static void {T}_ppredict{sfx}({T}_t *s)", "{"]
        src += [_smull(ln[4:] if ln.startswith("    ") else ln) for ln in _predict_cov(sums, q, P)]
        src += ["}", ""]
        src += [f"static void {T}_pupdate{sfx}({T}_t *s, int32_t y)", "{"] + _gains_cov(sums, q, P) + ["}", ""]
    src += [
        "/* One sample with c_r, c_v, c_a, c_e in their coarse formats, or a skip (rare: out of line). */",
        f"static __attribute__((noinline)) void {T}_core_c({T}_t *s, int32_t z, bool valid)",
        "{",
    ]
    src += _core_cov_coarse(c, P, T) + ["}", ""]
    src += [
        "/* One sample: predict (from the second sample on), then, if the sample is valid, the update",
        f" * with z [m/s^2] {p.vars['z'].fmt}. Inlined into update, skip and step (one copy on AVR, ACN_CORE). */",
        f"ACN_CORE void {T}_core({T}_t *s, int32_t z, bool valid)",
        "{",
    ]
    src += _core_fixed(c, P, T)
    src += ["}", ""]
    return src


def _clamp_defines(c: AxisCode, P: str) -> list[str]:
    p = c.p
    return [
        f"#define {P}_{nm} INT32_C({h}) /* clamp: |{key}| <= {h} 2^32 LSB"
        f" ({h * 2.0 ** (32 - p.vars[key].fmt.frac):.6g} m >= {bound:.6g} m) */"
        for nm, (key, bound, h) in c.clamps.items()
    ]


def _shared_names(prefix: str) -> tuple[str, str, str]:
    """The shared step's function prefix, state type and table type: PREFIX__ (two underscores), which no
    axis' names can take (an axis name begins with a letter)."""
    return f"{prefix}__", f"{prefix}__cov_t", f"{prefix}__k_t"


def _cov_uniform(c: AxisCode, prefix: str) -> str:
    """Axis c's step (_cov_step_fns) with every shift explicit, its constants' names replaced by their
    values and its own names by the shared ones: the text codegen.share.merge lines up across axes."""
    ax = c.p.design.axis.name
    P, T = f"{prefix.upper()}_{ax.upper()}", f"{prefix}_{ax}"
    fn, st, kt = _shared_names(prefix)
    tok = _EXPLICIT_SHIFTS.set(True)
    try:
        text = "\n".join(_cov_step_fns(c, P, T))
    finally:
        _EXPLICIT_SHIFTS.reset(tok)
    values = dict(re.findall(rf"^#define {P}_(\w+) (\S+)", "\n".join(_fixed_consts(c, P) + _clamp_defines(c, P)), re.M))
    # a name with no value here stays (and, the axes' names differing, merge says the steps cannot be shared)
    text = re.sub(rf"\b{P}_(\w+)\b", lambda m: values.get(m[1], m[0]), text)
    text = text.replace(f"{T}_t *s", f"{st} *s, const {kt} *acn_k __attribute__((unused))")
    text = re.sub(rf"\b{T}_(\w+)\(s\b", rf"{fn}\1(s, acn_k", text)
    return text.replace(f"{T}_", fn)


def _shared_c(sh: Shared, codes: list[AxisCode], prefix: str) -> tuple[list[str], list[str]]:
    """C of the shared step (AVR only), in two parts: before the axes, the state type every axis' state
    is read as, the table type and the step's declaration; after them, the step's functions (so that
    the first copy of each line in the file is the x axis' own, which every target but AVR compiles)."""
    fn, st, kt = _shared_names(prefix)
    axes = ", ".join(c.p.design.axis.name for c in codes)
    members = [f"    {t}{'' if t.endswith('*') else ' '}{n};" for t, n in state_members("covariance")]
    head = [
        f"/* ---- AVR: axes {axes} share one copy of the covariance step (codegen.share; its functions follow",
        " * the axes); each axis' constants and shifts in its own table in flash. Each axis' state is read as",
        " * this type, whose members are its own (may_alias: accesses through either type alias). Elsewhere",
        " * every axis has its own step, its constants and shifts compiled in. ---- */",
        "#if defined(__AVR__)",
        "typedef struct __attribute__((may_alias)) {",
        *members,
        f"}} {st};",
        "",
        "typedef struct {",
        *[f"    {m}" for m in sh.members],
        f"}} {kt};",
        "",
        f"ACN_CORE void {fn}core({st} *s, const {kt} *acn_k, int32_t z, bool valid);",
        "#endif",
        "",
    ]
    tail = [f"/* ---- AVR: the covariance step axes {axes} share (codegen.share) ---- */", "#if defined(__AVR__)"]
    return head, tail + [sh.text, "#endif", ""]


def _shared_axis(sh: Shared, i: int, c: AxisCode, prefix: str) -> list[str]:
    """Axis i's table and its T_core, which runs the shared step on it (AVR)."""
    fn, st, kt = _shared_names(prefix)
    T = f"{prefix}_{c.p.design.axis.name}"
    return [
        f"typedef char {T}_is_{st}[sizeof({T}_t) == sizeof({st}) ? 1 : -1];",
        f"static const {kt} {T}_k ACN_ROM = {{{', '.join(sh.inits[i])}}};",
        "",
        f"ACN_INLINE void {T}_core({T}_t *s, int32_t z, bool valid)",
        "{",
        f"    {fn}core(({st} *)s, &{T}_k, z, valid);",
        "}",
        "",
    ]


def _cov_entries(c: AxisCode, P: str, T: str, params: str, args: str, shared: list[str] | None = None) -> list[str]:
    """The covariance form: its step (_cov_step_fns; on AVR the shared one's table and call when given)
    and the entry points update, skip and step."""
    step = _cov_step_fns(c, P, T)
    src = step if shared is None else ["#if defined(__AVR__)", *shared, "#else", *step, "#endif", ""]
    src += [f"void {T}_update({T}_t *s, int32_t z)", "{", f"    {T}_core(s, z, true);", "}", ""]
    src += [
        "/* A sample that must be skipped (rail-clipped, missing capture): predict only. */",
        f"void {T}_skip({T}_t *s)",
        "{",
        f"    {T}_core(s, 0, false);",
        "}",
        "",
    ]
    src += [
        "/* Convert the raw input and run one step; returns false when the sample was skipped. */",
        f"bool {T}_step({T}_t *s, {params})",
        "{",
        "    int32_t z = 0;",
        f"    if (!{T}_convert({args}, &z)) {{",
        f"        {T}_skip(s); /* rare: the core inlined once, for valid samples only */",
        "        return false;",
        "    }",
        f"    {T}_core(s, z, true);",
        "    return true;",
        "}",
        "",
    ]
    return src


def _read_c(c: AxisCode, P: str, T: str) -> list[str]:
    """T_read: the states in their output formats (u = v / Ts)."""
    p, v = c.p, c.p.vars
    return [
        f"void {T}_read(const {T}_t *s, {T}_out_t *o)",
        "{",
        "    o->r = s->r;",
        f"    o->u = acn_mul64x32(s->v, {P}_RATE, {p.f('v') + p.consts['RATE'][1].frac - p.f('u_out')});"
        f" /* v / Ts: Q.{p.f('v')} -> {v['u_out'].fmt} */",
        "    o->a = s->a;",
        "    o->e = s->e;" if c.eoff is None else f"    o->e = s->eb + {P}_EOFF; /* eps */",
        "}",
        "",
    ]


def _manifest(c: AxisCode, T: str) -> dict:
    """The axis' entry of PREFIX.json: formats, constants, bounds, the checkpoint image, the schedule."""
    p, sched = c.p, c.sched
    man = {
        "axis": p.design.axis.name,
        "form": p.form,
        "variables": {
            k: {
                "unit": x.unit,
                "bound": x.bound,
                "format": x.fmt.name,
                "word": x.fmt.word,
                "frac": x.fmt.frac,
                "resolution": x.fmt.lsb,
                "saturates": x.saturates,
                "note": x.note,
            }
            for k, x in p.vars.items()
        },
        "constants": {k: {"value": val, "format": f.name, "int": q} for k, (val, f, q) in c.consts.items()},
        "l1": p.l1.__dict__ | {},
        "z_error": p.z_error,
        "state_bytes": c.layout.state_bytes,  # sizeof(T_t); None when it depends on the target (a pointer)
        # what the telemetry's checkpoint frames carry (codegen.frames, accelnav.link.replay): the image of
        # T_save / T_load; "row": where the gain schedule's row index lies in it and how many rows there are
        # (an index >= rows is a damaged image: T_load and the host decoder refuse it)
        "checkpoint": {
            "bytes": c.layout.ck_bytes,
            "save": f"{T}_save",
            "load": f"{T}_load",
            "row": None
            if sched is None
            else {"offset": c.layout.ck_offsets["seg"], "rows": sched.n_segments + 1, "table": f"{T}_seg"},
        },
        "e_state_offset": c.eoff,  # gain schedule: eps = eb + this (LSB of e); None: the state holds eps
    }
    if sched is not None:
        man["schedule"] = {
            "segments": sched.n_segments,
            "max_error": [float(e) for e in sched.max_error],
            "rel_tol": list(SCHEDULE_REL_TOL),
            "floor_lsb": list(SCHEDULE_FLOOR_LSB),
            "flash_bytes": (sched.n_segments + 1) * 24,
        }
    return man


def _axis_fixed(
    c: AxisCode, prefix: str, shared: list[str] | None = None
) -> tuple[list[str], list[str], list[str], dict]:
    """(header decls, cdef decls, source lines, manifest) of one planned axis; ``shared``: its table and
    core on AVR when the axes share one step (_shared_axis)."""
    p = c.p
    ax = p.design.axis.name
    P = f"{prefix.upper()}_{ax.upper()}"
    T = f"{prefix}_{ax}"
    fields = _fields_fixed(p, T)
    params, args, in_body = _input_fixed(p, P)
    struct, out_struct, protos = _axis_decls(p, T, fields, params)
    ck_bytes = c.layout.ck_bytes
    fmt_defs = [
        f"#define {P}_R_FRAC {p.f('r')}",
        f"#define {P}_U_FRAC {p.f('u_out')}",
        f"#define {P}_A_FRAC {p.f('a')}",
        f"#define {P}_E_FRAC {p.f('e')}",
        f"#define {P}_Z_FRAC {p.f('z')}",
        f"#define {P}_CK_BYTES {ck_bytes} /* bytes of the state's checkpoint image ({T}_save, {T}_load) */",
    ]
    header = fmt_defs + [""] + struct + [""] + out_struct + [""] + protos
    cdef = struct + out_struct + protos

    src = [f"/* ---- axis {ax}: {p.form} form ---- */", ""] + _fixed_consts(c, P) + [""]
    src += _clamp_defines(c, P)
    gs = p.form == "gain_schedule"
    src += (_gs_defines(c, P) if gs else []) + [""]
    src += _gs_table(c, P, T) if gs else []
    src += _init_c(c, T)
    src += [f"bool {T}_convert({params}, int32_t *z)", "{"] + in_body + ["}", ""]
    src += (
        _gs_gains_c(c, P, T) + _gs_entries(c, P, T, params, args) if gs else _cov_entries(c, P, T, params, args, shared)
    )
    src += _read_c(c, P, T)
    src += _checkpoint_c(c, P, T, fields)
    return header, cdef, src, _manifest(c, T)


def emit(
    model: Model,
    *,
    form: str | None = None,
    arith: str = "fixed",
    prefix: str = "accelnav",
) -> dict[str, str]:
    """All generated files of ``model`` as {name: text}: PREFIX.h, PREFIX.c, PREFIX.json. Both forms
    follow skipped samples (the gain schedule through codegen.follow)."""
    check_prefix(prefix)  # before any planning: a prefix that is no C identifier is refused outright
    refuse_calibrated(model)  # both arithmetics start from the MCU's raw input (an ADC code, a capture)
    form = form or model.filter.form
    if arith == "float32":
        return emit_f32(model, form=form, prefix=prefix)
    codes = plan(model, form)  # every number and every range check, before any text
    H, S, MAN = [], [], []
    sh = merge([_cov_uniform(c, prefix) for c in codes]) if form == "covariance" and len(codes) > 1 else None
    shared_tail = []
    if isinstance(sh, Shared):
        head, shared_tail = _shared_c(sh, codes, prefix)
        S += head
    elif sh is not None:
        S += [f"/* AVR: one step per axis, as everywhere: the axes' steps cannot be shared ({sh}) */", ""]
    for i, c in enumerate(codes):
        h, _, s, man = _axis_fixed(c, prefix, _shared_axis(sh, i, c, prefix) if isinstance(sh, Shared) else None)
        H += h + [""]
        S += s
        MAN.append(man)
    S += shared_tail
    return package(
        model,
        prefix,
        what_h=f"fixed-point {form} filter, one set per axis",
        what_c=f"fixed-point {form} filter. No floating point, no division, no heap.",
        declarations=H,
        source_includes=(
            "#include <limits.h> /* UINT_MAX: acn_clz32 */\n#include <stddef.h> /* offsetof */\n"
            "#if defined(__AVR__)\n#include <avr/pgmspace.h> /* PROGMEM, pgm_read_*: the tables in flash */\n#endif\n\n"
        ),
        source_prelude=runtime_text()
        + (recip_helpers() if any(c.p.form == "covariance" for c in codes) else "")
        + "\n",
        body=S,
        manifest={"arith": "fixed", "form": form, "axes": MAN},
    )
