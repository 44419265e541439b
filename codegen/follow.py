"""The gain schedule after skipped samples: the deviation of the covariance block from the schedule's.

A time-indexed schedule holds the Kalman gain of an uninterrupted run. After a skipped sample (ADC
rail, bad capture) the Kalman gain is no longer that (a gap of 38 samples at 100 Hz leaves K_a 79 %
and K_v 25x off for about 10 samples), so the gain-schedule C follows the skip: from the first
skipped sample it carries the deviation D = P - P_u of the seven-entry block of P (codegen.gains,
carried as in the covariance form: c = P H' per state and P_re, P_ve, P_ae; v = Ts u) from the
block P_u of the uninterrupted run, and uses K = K_u + dK (clamped to the gain's format after a long
gap). Once dK is back within the schedule's own stated accuracy, it drops D and returns to the
schedule.

Why a deviation and not the block itself: the block at the moment of the skip is not available
(P_re grows to ~34 while c_r stays ~1e-3: taken from a table even one segment stale, it leaves
K_r 10 % off for good). The deviation needs none of it. The predict P = F P F' + Q is linear and
the same Q enters both runs, so D = F D F' exactly; the update only needs c_u = P_u H' and
S_u = H P_u H' + R of the uninterrupted run, which the schedule's gains give: S_u = R / (1 - K_ua -
K_ue), c_u = K_u S_u. Per sample, with c = c_u + D_c and S = S_u + D_ca + D_ce:

    valid:   dK = (D_c - K_u (D_ca + D_ce)) / S;  K = K_u + dK
             D_c' = R dK                    (c^+ = c R / S = K R in both runs)
             D_Pie' = D_Pie - (K_ui D_ce + dK_i c_e),  i = r, v, a
    skipped: D_c' = D_c + K_u (S_u - R);  D_Pie' = D_Pie + K_ui c_ue   (the update only P_u had)

At D = 0 every term is exactly zero, whatever the schedule's compression error: the deviation decays
to zero as the Kalman gain returns to the uninterrupted one (measured: within the schedule's
tolerance 0.05-0.2 s after gaps of 1-38 samples at 100 Hz). The return is decided by that
measurement on the MCU: at a valid sample whose |dK| are all within the schedule's own tolerance at
that sample (:class:`Thresholds`: a fraction of |K_u| no larger than rel_tol, ramped like the schedule
for K_r and K_v, and a floor of an LSB or two), D is dropped and the next sample takes the schedule's
gains again. The threshold used to be each gain's largest compression error over the whole run: K_r
grows 600x over an hour, so a gap in the first seconds handed back with K_r up to ~20 % off and left
r and u 1.6-2.1e-3 sigma from the float64 filter (100 Hz shock, seeds 2 and 13).

The deviation entries are carried 2^z times their value (z <= ZOOM_MAX, in the state): their formats
hold the largest deviation after the longest gap planned, and as D decays after a short gap it would
sink to a few LSB of them (dK_r resolved to ~1e-3 of K_r at 1 kHz: the C followed for good, and r and a
ended 1.2-1.3e-3 sigma off). After each valid sample z grows while every entry is below 2^26; a skip
brings D back to z = 0 before its update, which is not small. The update is linear in D, so the zoom
only enters where D meets a quantity of its own scale: dS into S, D_ce into c_e, and dK out (rounded
from int64, then clamped); D_c = R dK and the D_Pie update are taken from num = S dK (num R / S, num
c_e / S), which stays within int32 at any zoom.

"Following" is bit 31 of the state's sample count k (codegen.emit_c._gs_entries): the common step
tests one word, k <= 0 (the first sample, or following a skip), and everything else, this module's C
included, runs out of line. The count itself is k's low 31 bits.

:func:`follow_plan` works out its numbers, :func:`emit_follow` writes the C from them; :class:`Follow`
is its integer twin (same operations on Python ints, bit for bit), from which :func:`followed_gains`
gives the exact gains the C uses on a run: codegen.bounds then takes |K_C - K_float64| per sample
exactly, for any skip pattern.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .qformat import quantize
from .ranges import DEV  # the deviation entries, planned in codegen.ranges._plan_schedule_follow

# the deviation entries are carried 2^z times their value, z <= ZOOM_MAX: as the deviation decays after a
# gap its entries fall far below the formats planned for its largest (a gap of many samples), and dK,
# which the return to the schedule waits on, would be resolved to a few parts in 1e3 of K_r at 1 kHz
ZOOM_MAX = 24

# --------------------------------------------------------------------------
# The operations, spelled once for C and once for Python ints


class _Ops:
    """Helpers shared by the emitter and the twin: the frac bits of every quantity."""

    def __init__(self, p):
        self.p = p
        f = {nm: p.f(nm) for nm in DEV}
        f["S"] = p.f("S")
        for n in "rvae":
            f["K" + n] = p.f("K" + n)
        for c in ("H2", "T2", "OMP", "PHI", "PHI2", "PHIOMP", "R"):
            f[c] = p.consts[c][1].frac
        self.f = f
        self.ci = {"r": "Dcr", "v": "Dcv", "a": "Dca", "e": "Dce"}
        self.pe = {"r": "DPre", "v": "DPve", "a": "DPae"}
        fS = f["S"]
        R_int = quantize(p.design.R, p.vars["S"].fmt)
        smax = p.vars["S"].fmt.qmax
        self.n_lo = 32 - smax.bit_length()  # clz of the largest S
        self.n_hi = 32 - R_int.bit_length()  # clz of the smallest (R)
        # dK_i = num_i x 2^(n-62) 2^(-fS) in Q.f_ci -> Q.fK_i: right shift SH_i - n
        self.sh = {n: 62 - fS - f["K" + n] + f[self.ci[n]] for n in "rvae"}
        for n, s in self.sh.items():  # the product num x uses x >> 1: the shift is s - 1 - n
            if s - 1 - self.n_hi < 1 or s - 1 - self.n_lo > 62:
                raise ValueError(f"dK_{n} shift {s} - n out of range for n in {self.n_lo}..{self.n_hi}")
        # c_e / S (the update's K_e of this prior), Q.fces: |c_e| < 2^(31 - f_ce), S >= R
        f["CES"] = f["Dce"] + math.floor(math.log2(p.design.R))
        self.thr = None


def _py_rshr(x: int, s: int) -> int:
    return (x + (1 << (s - 1))) >> s if s > 0 else x


def _py_term(a: int, fa: int, b: int, fb: int, fo: int) -> int:
    s = fa + fb - fo
    if s >= 63:
        return 0
    return _py_rshr(a * b, s)


def _py_align(a: int, fa: int, fo: int) -> int:
    return _py_rshr(a, fa - fo) if fa > fo else a << (fo - fa)


@dataclass(frozen=True)
class Thresholds:
    """When the C drops the deviation and returns to the schedule: at a valid sample where every gain's
    |dK_i| <= max(floor[i], |K_u,i| >> (shift[i] + extra)), K_u the schedule's gain of that sample, in LSB
    of its format; extra = 0, except for K_r and K_v (ramp[i]) before sample ``ramp``: the least e <= 5
    with (k + 1) 2^e >= ramp, as the schedule's own tolerance on them is tighter there (x (k + 1) / ramp,
    at least 1/20). The relative part 2^-shift is at most the schedule's rel_tol: after the return the
    dropped |dK| is within the schedule's own tolerance at that sample."""

    floor: tuple[int, ...]
    shift: tuple[int, ...]
    ramped: tuple[bool, ...]
    ramp: int

    def extra(self, k: int) -> int:
        e = 0
        while e < 5 and (k + 1) << e < self.ramp:
            e += 1
        return e

    def at(self, k: int, K) -> list[int]:
        """The threshold of each gain at sample k, schedule gains K (ints)."""
        e = self.extra(k)
        return [
            max(self.floor[i], abs(int(K[i])) >> min(31, self.shift[i] + (e if self.ramped[i] else 0)))
            for i in range(4)
        ]


def thresholds(sched) -> Thresholds:
    """The return thresholds of this plan's schedule (:class:`Thresholds`): relative ones from the
    schedule's rel_tol, the floor its absolute floor (at least one LSB)."""
    shift = tuple(min(31, max(0, math.ceil(-math.log2(r)))) if r > 0 else 31 for r in sched.tol)
    floor = tuple(max(1, math.ceil(f)) for f in sched.floor)
    return Thresholds(floor, shift, (True, True, False, False), max(1, sched.ramp))


# Every product of T_follow: (a, b, out) names of _Ops.f, a x b rounded from Q.(f_a + f_b) to Q.f_out; and
# every alignment (a, out). Listed once: follow_plan works out their shifts, emit_follow spells them.
_PRODUCTS = (
    ("H2", "DPae", "DPre"), ("T2", "DPae", "DPve"), ("H2", "Dca", "Dcr"), ("OMP", "DPre", "Dcr"),
    ("T2", "Dca", "Dcv"), ("OMP", "DPve", "Dcv"), ("OMP", "DPae", "Dca"), ("PHI2", "Dce", "Dce"),
    ("PHIOMP", "DPae", "Dce"), ("PHI", "DPre", "DPre"), ("PHI", "DPve", "DPve"), ("PHI", "DPae", "DPae"),
    ("Kr", "S", "Dcr"), ("Kv", "S", "Dcv"), ("Ka", "S", "Dca"), ("Ke", "S", "Dce"),
    ("Kr", "Dce", "DPre"), ("Kv", "Dce", "DPve"), ("Ka", "Dce", "DPae"),
    ("Dcr", "CES", "DPre"), ("Dcv", "CES", "DPve"), ("Dca", "CES", "DPae"),
    ("Dcr", "RS", "Dcr"), ("Dcv", "RS", "Dcv"), ("Dca", "RS", "Dca"), ("Dce", "RS", "Dce"),
)  # fmt: skip
_ALIGNS = (("DPve", "DPre"), ("Dcv", "Dcr"), ("Ka", "W"), ("Ke", "W"), ("Dca", "S"), ("Dce", "S"))


@dataclass(frozen=True)
class FollowPlan:
    """Every number T_follow's C carries, worked out and checked before any text: the return thresholds,
    the frac bits, the right shift of every product (>= 63: below one LSB of its target, dropped), the
    alignment of every sum's terms (> 0 a right shift, else a left one), the dK shifts SH_i (the C takes
    SH_i - 1 - n) and c_e / S's, and which ramped threshold shifts need a cap at 31."""

    thr: Thresholds
    f: dict[str, int]
    products: dict[tuple[str, str, str], int]
    aligns: dict[tuple[str, str], int]
    dk_shift: dict[str, int]
    ces_shift: int
    capped: tuple[bool, ...]


def follow_plan(p, thr: Thresholds) -> FollowPlan:
    """The plan of T_follow for these formats; ValueError when the deviation's formats need a shift the C
    cannot take (a dK shift out of 1..62 for some clz of S, :class:`_Ops`, or a left-shifted product)."""
    o = _Ops(p)
    f = o.f | {"RS": 30, "W": 30}  # R / S in Q1.30; 1 - K_ua - K_ue in Q.30
    products = {}
    for a, b, out in _PRODUCTS:
        s = f[a] + f[b] - f[out]
        if s < 0:
            raise ValueError(f"product {a} * {b}: left shift")
        products[(a, b, out)] = s
    aligns = {(a, out): f[a] - f[out] for a, out in _ALIGNS}
    capped = tuple(thr.shift[i] + 5 > 31 and thr.ramped[i] for i in range(4))
    ces_shift = 61 - f["S"] + f["Dce"] - f["CES"]  # 1/S = x 2^(n - 62 + fS), x = 2 xs
    return FollowPlan(thr, f, products, aligns, dict(o.sh), ces_shift, capped)


def emit_follow(fp: FollowPlan, P: str, T: str) -> list[str]:
    """C: T_follow(s, valid, K): one sample of the deviation recursion (see the module docstring), spelled
    from its plan. K in: the schedule's gains K_u of this sample; out (valid): the gains to use."""
    f, thr = fp.f, fp.thr
    fS = f["S"]
    ci = {"r": "Dcr", "v": "Dcv", "a": "Dca", "e": "Dce"}
    pe = {"r": "DPre", "v": "DPve", "a": "DPae"}

    def sat(expr):
        return f"acn_sat32({expr}, &s->overflow)"

    def k(name):
        return f"{P}_{name}"

    def term(a: str, b: str, key: tuple[str, str, str]) -> str:
        """(int64_t)a * b rounded to the key's target (codegen.follow._PRODUCTS)."""
        s = fp.products[key]
        if s == 0:
            return f"acn_mul({a}, {b})"
        if s >= 63:
            return "0"
        return f"ACN_RSHR(acn_mul({a}, {b}), {s})"

    def align(a: str, key: tuple[str, str]) -> str:
        s = fp.aligns[key]
        if s > 0:
            return f"ACN_RSHR((int64_t){a}, {s})"
        return f"((int64_t){a} * ((int64_t)1 << {-s}))"

    H2, T2, OMP, PHI, PHI2, PHIOMP, R = (k(n) for n in ("H2", "T2", "OMP", "PHI", "PHI2", "PHIOMP", "R"))
    tr = "(int64_t)s->DPre + " + align("s->DPve", ("DPve", "DPre")) + " + "
    tr += term(H2, "s->DPae", ("H2", "DPae", "DPre"))
    tv = "(int64_t)s->DPve + " + term(T2, "s->DPae", ("T2", "DPae", "DPve"))
    dcr = "(int64_t)s->Dcr + " + align("s->Dcv", ("Dcv", "Dcr")) + " + "
    dcr += term(H2, "s->Dca", ("H2", "Dca", "Dcr")) + " - " + term(OMP, "tr", ("OMP", "DPre", "Dcr"))
    dcv = "(int64_t)s->Dcv + " + term(T2, "s->Dca", ("T2", "Dca", "Dcv"))
    dcv += " - " + term(OMP, "tv", ("OMP", "DPve", "Dcv"))
    dca = "(int64_t)s->Dca - " + term(OMP, "s->DPae", ("OMP", "DPae", "Dca"))
    dce = term(PHI2, "s->Dce", ("PHI2", "Dce", "Dce")) + " + " + term(PHIOMP, "s->DPae", ("PHIOMP", "DPae", "Dce"))
    zmax = ZOOM_MAX
    wa = align("K[2]", ("Ka", "W"))
    we = align("K[3]", ("Ke", "W"))
    L = [
        "/* back on the schedule once every |dK| <= max(FLOOR, |K_u| >> (SH + e)), e > 0 for K_r and K_v",
        " * before sample RAMP (codegen.follow.Thresholds) */",
        *(f"#define {P}_FLOOR_{c} UINT32_C({thr.floor[i]})" for i, c in enumerate("RVAE")),
        *(f"#define {P}_SH_{c} {thr.shift[i]}" for i, c in enumerate("RVAE")),
        f"#define {P}_RAMP UINT32_C({thr.ramp})",
        "",
        "#ifndef ACN_CLAMP32",
        "#define ACN_CLAMP32",
        "/* x / 2^z, rounded (z >= 0) */",
        "static inline int32_t acn_unzoom(int32_t x, int z)",
        "{",
        "    return z ? (int32_t)(((int64_t)x + ((int64_t)1 << (z - 1))) >> z) : x;",
        "}",
        "static inline int64_t acn_unzoom64(int64_t x, int z)",
        "{",
        "    return z ? (x + ((int64_t)1 << (z - 1))) >> z : x;",
        "}",
        "/* int64 -> int32, clamped and not counted: a gain after a long gap beyond its format (codegen.follow:",
        " * the stated bound takes the clamped gain) */",
        "static inline int32_t acn_clamp32(int64_t x)",
        "{",
        "    return x > INT32_MAX ? INT32_MAX : x < INT32_MIN ? INT32_MIN : (int32_t)x;",
        "}",
        "#endif",
        "",
        "/* After a skipped sample: the deviation D = P - P_u of the covariance block from the uninterrupted",
        " * run's, carried until the gains are back on the schedule (codegen.follow). K: in, the schedule's",
        " * gains of this sample [r, v, a, e]; out (valid samples), the gains to use. Rare: not inlined. */",
        f"static __attribute__((noinline)) void {T}_follow({T}_t *s, bool valid, int32_t K[4])",
        "{",
        "    int32_t w, Su, cu[4];",
        "    int32_t *const d[7] = {&s->Dcr, &s->DPre, &s->Dcv, &s->DPve, &s->Dca, &s->DPae, &s->Dce}; /* D */",
        "    uint32_t x;",
        "    int n;",
        f"    if (s->k & {P}_FOLLOWING) {{",
        f"        if ((s->k & ~{P}_FOLLOWING) > 0) {{",
        "            /* D = F D F' (the same Q enters both runs); right-hand sides read the old values */",
        "            int32_t tr, tv;",
        f"            tr = {sat(tr)};",
        f"            tv = {sat(tv)};",
        f"            s->Dcr = {sat(dcr)};",
        f"            s->Dcv = {sat(dcv)};",
        f"            s->DPre = (int32_t){term(PHI, 'tr', ('PHI', 'DPre', 'DPre'))};",
        f"            s->DPve = (int32_t){term(PHI, 'tv', ('PHI', 'DPve', 'DPve'))};",
        f"            s->Dca = {sat(dca)};",
        f"            s->Dce = {sat(dce)};",
        f"            s->DPae = (int32_t){term(PHI, 's->DPae', ('PHI', 'DPae', 'DPae'))};",
        "        }",
        "    } else {",
        "        /* the first skip of an excursion: P equals P_u here */",
        f"        s->k |= {P}_FOLLOWING;",
        "        s->Dcr = s->DPre = s->Dcv = s->DPve = s->Dca = s->DPae = s->Dce = 0;",
        "        s->z = 0;",
        "    }",
        "    /* S_u = R / (1 - K_ua - K_ue), 1 - K_ua - K_ue in Q.30; c_u = K_u S_u */",
        f"    w = (int32_t)((int64_t)((int64_t)1 << 30) - (int32_t){wa} - (int32_t){we});",
        "    x = acn_recip((uint32_t)w, &n); /* 1/w = x 2^(n-62) */",
        f"    Su = {sat(f'ACN_RSHR((int64_t){R} * (int64_t)x, 32 - n)')}; /* Q.{fS} */",
    ]
    for i, nm in enumerate("rvae"):
        L.append(f"    cu[{i}] = {sat(term(f'K[{i}]', 'Su', ('K' + nm, 'S', ci[nm])))};")
    dS = align("s->Dca", ("Dca", "S")) + " + " + align("s->Dce", ("Dce", "S"))
    ces_sh = fp.ces_shift
    L += [
        "    if (valid) {",
        "        int32_t dS, S, xs, dK[4], num[4], ce, rs, ces;",
        "        int z = (int)s->z; /* the D entries, dS and num below are 2^z times their values */",
        f"        dS = {sat(dS)};",
        "        S = acn_add_sat32(Su, acn_unzoom(dS, z), &s->overflow);",
        f"        if (S < {R}) {{",
        f"            S = {R};",
        "        }",
        "        x = acn_recip((uint32_t)S, &n); /* 1/S = x 2^(n-62) */",
        "        xs = (int32_t)(x >> 1); /* x < 2^31 after the shift: a signed 32x32 product */",
        "        ce = acn_add_sat32(cu[3], acn_unzoom(s->Dce, z), &s->overflow);"
        f" /* c_e of this prior, Q.{f['Dce']} */",
        f"        rs = (int32_t)ACN_RSHR(acn_mul({R}, xs), 31 - n); /* R / S, Q1.30 */",
        f"        ces = {sat(f'ACN_RSHR(acn_mul(ce, xs), {ces_sh} - n)')}; /* c_e / S, Q.{f['CES']} */",
    ]
    for i, nm in enumerate("rvae"):
        dc = ci[nm]
        num = f"(int64_t)s->{dc} - " + term(f"K[{i}]", "dS", ("K" + nm, "S", dc))
        dks = fp.dk_shift[nm] - 1
        L += [
            f"        /* dK_{nm} = (D_c{nm} - K_u{nm} dS) / S = num / S */",
            f"        num[{i}] = {sat(num)};",
            f"        dK[{i}] = acn_clamp32(acn_unzoom64(ACN_RSHR(acn_mul(num[{i}], xs), {dks} - n), z));",
        ]
    L += ["        /* D_Pie -= K_ui D_ce + dK_i c_e (the old D_ce); D_c = R dK = num R / S */"]
    for i, nm in enumerate("rva"):
        t1 = term(f"K[{i}]", "s->Dce", ("K" + nm, "Dce", pe[nm]))
        t2 = term(f"num[{i}]", "ces", (ci[nm], "CES", pe[nm]))
        L.append(f"        s->{pe[nm]} = {sat(f'(int64_t)s->{pe[nm]} - {t1} - {t2}')};")
    for i, nm in enumerate("rvae"):
        L.append(f"        s->{ci[nm]} = {sat(term(f'num[{i}]', 'rs', (ci[nm], 'RS', ci[nm])))};")
    L += [
        "        /* back on the schedule once every |dK| is within its threshold */",
        "        {",
        "            uint32_t kk = (s->k & ~" + P + "_FOLLOWING) + 1u, t[4];",
        "            int e = 0, back = 1;",
        f"            while (e < 5 && kk < {P}_RAMP) {{ /* (k + 1) 2^e >= RAMP */",
        "                kk <<= 1;",
        "                e++;",
        "            }",
    ]
    for i, c in enumerate("RVAE"):
        sh = f"({P}_SH_{c} + e)" if thr.ramped[i] else f"{P}_SH_{c}"
        cap = f"({sh} > 31 ? 31 : {sh})" if fp.capped[i] else sh
        L += [
            f"            t[{i}] = (K[{i}] < 0 ? 0u - (uint32_t)K[{i}] : (uint32_t)K[{i}]) >> {cap};",
            f"            t[{i}] = t[{i}] < {P}_FLOOR_{c} ? {P}_FLOOR_{c} : t[{i}];",
        ]
    L += [
        "            for (int i = 0; i < 4; i++) {",
        "                back &= (uint32_t)dK[i] + t[i] <= 2u * t[i];",
        "            }",
        "            if (back) {",
        f"                s->k &= ~{P}_FOLLOWING;",
        "            }",
        "        }",
        "        {",
        "            /* zoom in while every D entry is below 2^27 (they shrink as the deviation decays) */",
        "            uint32_t m = 0;",
        "            int g = 0;",
        "            for (int i = 0; i < 7; i++) {",
        "                m |= *d[i] < 0 ? 0u - (uint32_t)*d[i] : (uint32_t)*d[i];",
        "            }",
        f"            while (z + g < {zmax} && m < (UINT32_C(1) << 26)) {{",
        "                m <<= 1;",
        "                g++;",
        "            }",
        "            for (int i = 0; i < 7; i++) {",
        "                *d[i] = (int32_t)((uint32_t)*d[i] << g);",
        "            }",
        "            s->z = (uint32_t)(z + g);",
        "        }",
    ]
    for i in range(4):
        L.append(f"        K[{i}] = acn_clamp32((int64_t)K[{i}] + dK[{i}]);")
    L += [
        "    } else {",
        "        /* skipped: D += the update only P_u had: c_i -= K_ui (S_u - R), P_ie -= K_ui c_ue; D at",
        "         * zoom 0 first (the update is not small) */",
        "        if (s->z) {",
        "            for (int i = 0; i < 7; i++) {",
        "                *d[i] = acn_unzoom(*d[i], (int)s->z);",
        "            }",
        "            s->z = 0;",
        "        }",
    ]
    L.append(f"        int32_t sr = Su - {R};")
    for i, nm in enumerate("rvae"):
        dc = ci[nm]
        L.append(f"        s->{dc} = {sat(f'(int64_t)s->{dc} + ' + term(f'K[{i}]', 'sr', ('K' + nm, 'S', dc)))};")
    for i, nm in enumerate("rva"):
        inc = term(f"K[{i}]", "cu[3]", ("K" + nm, "Dce", pe[nm]))
        L.append(f"        s->{pe[nm]} = {sat(f'(int64_t)s->{pe[nm]} + ' + inc)};")
    L += ["    }", "}", ""]
    return L


# --------------------------------------------------------------------------
# The integer twin

_M32 = 0xFFFFFFFF


def _i32(x: int) -> int:
    x &= _M32
    return x - (1 << 32) if x & 0x80000000 else x


def _clamp(x: int) -> int:
    return min(max(x, -(2**31)), 2**31 - 1)


def _umulhi(a: int, b: int) -> int:
    return ((a & _M32) * (b & _M32)) >> 32


def recip(d: int) -> tuple[int, int]:
    """acn_recip of the generated C, on Python ints: (x, n) with 1/d = x 2^(n-62)."""
    n = 32 - d.bit_length()
    dn = (d << n) & _M32
    x = (3031741621 - _umulhi(2021161080, dn)) & _M32
    for _ in range(3):
        err = _i32(0x40000000 - _umulhi(dn, x))
        x = (x + ((_i32(x >> 1) * err) >> 29)) & _M32
    return x, n


class Follow:
    """The C's T_follow on Python ints, bit for bit (saturations counted in ``overflow``)."""

    def __init__(self, p, thr: Thresholds):
        self.o = o = _Ops(p)
        self.f = o.f
        self.q = {
            c: quantize(p.consts[c][0], p.consts[c][1]) for c in ("H2", "T2", "OMP", "PHI", "PHI2", "PHIOMP", "R")
        }
        self.thr = thr
        self.dev = False
        self.D = dict.fromkeys(DEV, 0)
        self.z = 0
        self.overflow = 0

    def _sat(self, x: int) -> int:
        if x > 2**31 - 1 or x < -(2**31):
            self.overflow += 1
            return 2**31 - 1 if x > 0 else -(2**31)
        return x

    def step(self, k: int, valid: bool, K: list[int]) -> list[int]:
        f, q, D, sat = self.f, self.q, self.D, self._sat
        t, al = _py_term, _py_align
        if self.dev:
            if k > 0:
                tr = sat(
                    D["DPre"]
                    + al(D["DPve"], f["DPve"], f["DPre"])
                    + t(q["H2"], f["H2"], D["DPae"], f["DPae"], f["DPre"])
                )
                tv = sat(D["DPve"] + t(q["T2"], f["T2"], D["DPae"], f["DPae"], f["DPve"]))
                D["Dcr"] = sat(
                    D["Dcr"]
                    + al(D["Dcv"], f["Dcv"], f["Dcr"])
                    + t(q["H2"], f["H2"], D["Dca"], f["Dca"], f["Dcr"])
                    - t(q["OMP"], f["OMP"], tr, f["DPre"], f["Dcr"])
                )
                D["Dcv"] = sat(
                    D["Dcv"]
                    + t(q["T2"], f["T2"], D["Dca"], f["Dca"], f["Dcv"])
                    - t(q["OMP"], f["OMP"], tv, f["DPve"], f["Dcv"])
                )
                D["DPre"] = _i32(t(q["PHI"], f["PHI"], tr, f["DPre"], f["DPre"]))
                D["DPve"] = _i32(t(q["PHI"], f["PHI"], tv, f["DPve"], f["DPve"]))
                D["Dca"] = sat(D["Dca"] - t(q["OMP"], f["OMP"], D["DPae"], f["DPae"], f["Dca"]))
                D["Dce"] = sat(
                    t(q["PHI2"], f["PHI2"], D["Dce"], f["Dce"], f["Dce"])
                    + t(q["PHIOMP"], f["PHIOMP"], D["DPae"], f["DPae"], f["Dce"])
                )
                D["DPae"] = _i32(t(q["PHI"], f["PHI"], D["DPae"], f["DPae"], f["DPae"]))
        else:
            self.dev = True
            for nm in DEV:
                D[nm] = 0
            self.z = 0
        fS = f["S"]
        w = _i32((1 << 30) - _i32(al(K[2], f["Ka"], 30)) - _i32(al(K[3], f["Ke"], 30)))
        x, n = recip(w & _M32)
        Su = sat(_py_rshr(q["R"] * x, 32 - n))
        ci, pe = self.o.ci, self.o.pe
        cu = [sat(t(K[i], f["K" + nm], Su, fS, f[ci[nm]])) for i, nm in enumerate("rvae")]
        K = list(K)
        if valid:
            z = self.z
            dS = sat(al(D["Dca"], f["Dca"], fS) + al(D["Dce"], f["Dce"], fS))
            S = sat(Su + _py_rshr(dS, z))
            S = max(S, q["R"])
            x, n = recip(S)
            xs = _i32(x >> 1)
            ce = sat(cu[3] + _py_rshr(D["Dce"], z))
            rs = _i32(_py_rshr(q["R"] * xs, 31 - n))
            ces = sat(_py_rshr(ce * xs, 61 - fS + f["Dce"] - f["CES"] - n))
            num, dK = [], []
            for i, nm in enumerate("rvae"):
                num.append(sat(D[ci[nm]] - t(K[i], f["K" + nm], dS, fS, f[ci[nm]])))
                dK.append(_clamp(_py_rshr(_py_rshr(num[i] * xs, self.o.sh[nm] - 1 - n), z)))
            for i, nm in enumerate("rva"):
                D[pe[nm]] = sat(
                    D[pe[nm]]
                    - t(K[i], f["K" + nm], D["Dce"], f["Dce"], f[pe[nm]])
                    - t(num[i], f[ci[nm]], ces, f["CES"], f[pe[nm]])
                )
            for i, nm in enumerate("rvae"):
                D[ci[nm]] = sat(t(num[i], f[ci[nm]], rs, 30, f[ci[nm]]))
            back = self.thr.at(k, K)
            if all(abs(dK[i]) <= back[i] for i in range(4)):
                self.dev = False
            m = 0
            for nm in DEV:
                m |= abs(D[nm])
            g = 0
            while z + g < ZOOM_MAX and m < 1 << 26:
                m <<= 1
                g += 1
            for nm in DEV:
                D[nm] = _i32(D[nm] << g)
            self.z = z + g
            K = [_clamp(K[i] + dK[i]) for i in range(4)]
        else:
            if self.z:
                for nm in DEV:
                    D[nm] = _py_rshr(D[nm], self.z)
                self.z = 0
            sr = Su - q["R"]
            for i, nm in enumerate("rvae"):
                D[ci[nm]] = sat(D[ci[nm]] + t(K[i], f["K" + nm], sr, fS, f[ci[nm]]))
            for i, nm in enumerate("rva"):
                D[pe[nm]] = sat(D[pe[nm]] + t(K[i], f["K" + nm], cu[3], f["Dce"], f[pe[nm]]))
        return K


def followed_gains(p, sched_int: np.ndarray, valid: np.ndarray, thr: Thresholds):
    """The gains the gain-schedule C uses at every sample of a run with this skip pattern: (n, 4) ints
    in the formats of K_r, K_v, K_a, K_e (C coordinates), and the samples that followed a skip (bool).
    ``sched_int``: the schedule's integer gains of the first n samples (Schedule.gains_int)."""
    fl = Follow(p, thr)
    out = np.array(sched_int, dtype=np.int64, copy=True)
    dev = np.zeros(len(out), dtype=bool)
    vl = np.asarray(valid, dtype=bool)
    skips = np.flatnonzero(~vl)
    if not len(skips):
        return out, dev
    k = int(skips[0])
    n = len(out)
    while k < n:
        if fl.dev or not vl[k]:
            dev[k] = True
            K = fl.step(k, bool(vl[k]), [int(x) for x in out[k]])
            if vl[k]:
                out[k] = K
            k += 1
        else:
            nxt = np.flatnonzero(~vl[k:])
            if not len(nxt):
                break
            k += int(nxt[0])
    return out, dev
