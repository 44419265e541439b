"""The covariance form's sums, planned: every constant folded, every shift and guard chosen, every
"fits int32" decided here, so that :mod:`codegen.emit_c` only spells them.

A sum is a list of :class:`Term` (a constant, an int32 variable, or their product, each with its binary
point). :func:`cov_sums` turns the predict of the carried block and the measurement update of one view of
the plan (fine or coarse formats) into :class:`CovSums`: per entry of the block, which of the C shapes
computes it (one SMLAL chain into a high word, :class:`HSum`; a sum rounded once, :class:`Acc`) and
whether it needs a saturation.
"""

from __future__ import annotations

from dataclasses import dataclass

from .qformat import QFormat, acc_bound, guard_bits, quantize
from .ranges import AxisPlan


@dataclass(frozen=True)
class Term:
    """sign (const [* var]) or sign var, in Q.frac; const "-NAME" is the constant negated in its literal
    (no 64-bit negation of the product)."""

    sign: str
    const: str | None
    var: str | None
    frac: int

    @property
    def neg(self) -> bool:
        return self.const is not None and self.const.startswith("-")

    @property
    def name(self) -> str:
        return self.const.lstrip("-")


def _k(const: str, frac: int, var: str | None = None) -> Term:
    return Term("+", const, var, frac)


def _v(var: str, frac: int) -> Term:
    return Term("+", None, var, frac)


@dataclass(frozen=True)
class Acc:
    """Sum rounded once to Q.ft: ``exact`` terms already in Q.ft; ``fine`` ones each floored by its shift
    (0: none) to Q.(ft + g), summed with the rounding offset (half an LSB, or ``dither``'s top g bits)."""

    ft: int
    exact: tuple[Term, ...]
    fine: tuple[tuple[Term, int], ...]
    g: int
    dither: str | None


@dataclass(frozen=True)
class HSum:
    """Sum in one int64 accumulator in Q.F = Q.(ft + 32), its high word the int32 result in Q.ft: ``lit``
    the folded constants, ``ops`` (variable, its right shift, int32 multiplier, and for the comment the
    constant's value and the multiplier's Q, or (None, e) for a power of two 2^e), ``bound`` on |result|
    in LSB for any int32 variables."""

    ft: int
    F: int
    lit: int
    ops: tuple[tuple[str, int, int, tuple[float | None, int]], ...]
    bound: int
    dither: str | None


@dataclass(frozen=True)
class CovSums:
    """One view (fine or coarse) of the covariance form: its predict entries and update decisions.

    predict: entry -> (shape, first term's variable or None, HSum | Acc), shapes: "hadd" (x0 plus an HSum,
    one saturating 32-bit add), "addsat" (the same with an Acc), "sat" (a saturated Acc), "h" (x0 plus an
    HSum, no saturation: a decay), "acc" (an Acc, no saturation), and for c_e "free" (c_e plus an HSum
    checked to fit int32 at the corners)."""

    view: AxisPlan  # the plan in the formats these sums are in (codegen.ranges.fine_view, or the coarse one)
    predict: dict[str, tuple[str, str | None, HSum | Acc]]
    s_fits: bool  # S = c_a + c_e aligned + R as one saturating 32-bit add
    ke_free: bool  # K_e = c_e / S fits int32 for any c_e: no saturation
    fracs: dict  # the update's binary points (cov_fracs)


def acc_of(ft: int, terms: list[Term], dither: str | None = None) -> Acc:
    exact = tuple(t for t in terms if t.frac == ft)
    fine = [t for t in terms if t.frac != ft]
    if any(t.frac < ft for t in fine):
        raise ValueError("a term coarser than its target")
    g = guard_bits([t.frac for t in fine], ft) if fine else 0
    shifts = tuple((t, t.frac - ft - g if t.frac - ft > g else 0) for t in fine)
    return Acc(ft, exact, shifts, g, dither if fine and g <= 32 else None)


def hsum_of(p: AxisPlan, ft: int, terms: list[Term], dither: str | None = None) -> HSum | None:
    """Each constant of a product scaled so that the product lands in Q.(ft + 32) (one SMLAL, no shift;
    when that leaves the constant fewer than 20 bits, the variable is first shifted right by the k that
    best balances the constant's rounding against the variable's floor), each variable by a power of two,
    the constants and the rounding offset start the accumulator. None when a term does not fit that."""
    F = ft + 32
    lit = 0
    ops = []
    mag = 0
    for t in terms:
        if t.const is not None:
            val = p.consts[t.name][0] * (-1.0 if t.neg else 1.0) * (-1.0 if t.sign == "-" else 1.0)
            if t.var is None:  # a constant: into the start of the accumulator
                lit += quantize(val, QFormat(64, F))
                continue
            fv = t.frac - p.consts[t.name][1].frac  # the variable's own binary point
            kk = val * 2.0 ** (F - fv)
            if abs(kk) >= 2**30:
                return None
            k = 0
            if abs(kk) < 2**20:
                ks = [j for j in range(25) if abs(kk) * 2.0**j < 2**30]
                k = min(ks, key=lambda j: 2.0 ** (30 - j) + abs(kk) * 2.0**j)
            ki = quantize(kk * 2.0**k, QFormat(32, 0))
            ops.append((t.var, k, ki, (val, F - fv + k)))
            mag += abs(ki) * 2 ** (31 - k)
            continue
        if 0 <= F - t.frac <= 30:  # an int32 variable times a power of two
            ops.append((t.var, 0, -(1 << (F - t.frac)) if t.sign == "-" else 1 << (F - t.frac), (None, F - t.frac)))
            mag += 2 ** (31 + F - t.frac)
            continue
        return None
    total = mag + abs(lit) + 2**32
    if total >= 2**62:
        return None
    return HSum(ft, F, lit, tuple(ops), (total >> 32) + 1, dither)


def hsum_at(h: HSum, values: dict, offset: int) -> int:
    """The int32 an HSum computes for the variables in ``values`` (name -> int) and rounding offset."""
    acc = h.lit + offset
    for x, k, ki, _ in h.ops:
        acc += ki * (values[x] >> k)
    return acc >> 32


def predict_terms(p: AxisPlan) -> dict[str, tuple[int, list[Term]]]:
    """The predict sums of the carried block: name -> (target frac bits, terms).

    Every constant has its own scaling (Q_ra, Q_ua, Q_aa, Q_ee and 1 - phi are far below the LSB of
    the entry they feed: in the entry's format Q_ra at 1 kHz was 6 LSB for 5.7, a 5 % error that
    biased c_r and with it K_r), so each enters as a fine term, aligned with the products. The decay
    by phi is written as x - (1 - phi) x, (1 - phi) in its own scaling, for the same reason."""
    fcr, fPr, fcv, fPv, fca, fPae, fce = (p.f(n) for n in ("cr", "Pre", "cv", "Pve", "ca", "Pae", "ce"))
    fq = {n: p.consts[n][1].frac for n in ("H2", "T2", "OMPC", "PHIOMP", "Qra", "Qva", "Qaa", "Qee")}
    H2, T2, OMP, PO = fq["H2"], fq["T2"], fq["OMPC"], fq["PHIOMP"]
    return {
        "tr": (fPr, [_v("s->Pre", fPr), _v("s->Pve", fPv), _k("H2", H2 + fPae, "s->Pae")]),
        "tv": (fPv, [_v("s->Pve", fPv), _k("T2", T2 + fPae, "s->Pae")]),
        "cr": (
            fcr,
            [
                _v("s->cr", fcr),
                _v("s->cv", fcv),
                _k("H2", H2 + fca, "s->ca"),
                _k("Qra", fq["Qra"]),
                _k("-OMPC", OMP + fPr, "tr"),
            ],
        ),
        "cv": (
            fcv,
            [_v("s->cv", fcv), _k("T2", T2 + fca, "s->ca"), _k("Qva", fq["Qva"]), _k("-OMPC", OMP + fPv, "tv")],
        ),
        "Pre": (fPr, [_v("tr", fPr), _k("-OMPC", OMP + fPr, "tr")]),
        "Pve": (fPv, [_v("tv", fPv), _k("-OMPC", OMP + fPv, "tv")]),
        "ca": (fca, [_v("s->ca", fca), _k("Qaa", fq["Qaa"]), _k("-OMPC", OMP + fPae, "s->Pae")]),
        "ce": (fce, [_k("PHI2", 31 + fce, "s->ce"), _k("PHIOMP", PO + fPae, "s->Pae"), _k("Qee", fq["Qee"])]),
        "Pae": (fPae, [_v("s->Pae", fPae), _k("-OMPC", OMP + fPae, "s->Pae")]),
    }


DITHERED = ("Pre", "Pve", "Pae")  # entries whose change per sample is a small fraction of their LSB


def _mag(p: AxisPlan, t: Term) -> int:
    """A bound on |term| in its own LSB for any int32 operands."""
    if t.const is None:
        return 2**31
    v, fmt = p.consts[t.name]
    return abs(quantize(v, fmt)) * (2**31 if t.var else 1)


def _sat(p: AxisPlan, ft: int, terms: list[Term]):
    """x0 + rest as one saturating 32-bit add when the rest fits int32 for any int32 inputs (the same
    integer and overflow count as saturating the 64-bit sum), else the 64-bit sum saturated."""
    x0, rest = terms[0], terms[1:]
    first = x0.const is None and x0.sign == "+" and x0.frac == ft
    h = hsum_of(p, ft, rest)
    if h is not None and first and h.bound < 2**31 - 1:
        return ("hadd", x0.var, h)
    if first and rest and acc_bound(ft, [(_mag(p, t), t.frac) for t in rest]) < 2**31 - 1:
        return ("addsat", x0.var, acc_of(ft, rest))
    return ("sat", None, acc_of(ft, terms))


def _ce(p: AxisPlan, t: dict):
    """c_e' = c_e - (1 - phi^2) c_e + phi (1 - phi) P_ae + Q_ee with no clamp when it fits int32 at every
    corner of the int32 square of (c_e, P_ae) (c_e' is monotone in each: the coefficient of c_e,
    1 - (1 - phi^2), is below one and its floor moves it by < 1); else one saturating 32-bit add of c_e
    and the rest when the rest fits int32 for any inputs; else the sum of t["ce"] rounded once."""
    fce = p.f("ce")
    terms_ce = [_v("s->ce", fce), _k("-OMP2", p.consts["OMP2"][1].frac + fce, "s->ce")] + t["ce"][1][1:]
    h = hsum_of(p, fce, terms_ce[1:])
    if h is not None and "ce" in p.sat_free:
        corners = [(ce, pae) for ce in (-(2**31), 2**31 - 1) for pae in (-(2**31), 2**31 - 1)]
        if all(-(2**31) <= ce + hsum_at(h, {"s->ce": ce, "s->Pae": pae}, 2**31) <= 2**31 - 1 for ce, pae in corners):
            return ("free", "s->ce", h)
    if h is not None and h.bound < 2**31 - 1:
        return ("hadd", "s->ce", h)
    return ("acc" if "ce" in p.sat_free else "sat", None, acc_of(*t["ce"]))


def cov_fracs(p: AxisPlan) -> dict:
    """Binary points of the covariance form's update: nmax, the clz of the smallest S (= R); x, the
    format of xs = 1/S; and per state the product c_i w that it adds."""
    fca = p.f("ca")
    nmax = 32 - quantize(p.design.R, p.vars["S"].fmt).bit_length()
    fw = p.f("w")
    prod = {"r": p.f("cr") + fw, "v": p.f("cv") + fw, "a": fca + fw, "e": p.f("ce") + fw}
    return {"nmax": nmax, "x": 61 - nmax - fca, "prod": prod}


def _update_fits(p: AxisPlan) -> tuple[bool, bool, dict]:
    """(S's add fits one saturating 32-bit add, K_e needs no saturation, the update's binary points)."""
    fca, fce, fKe = p.f("ca"), p.f("ce"), p.f("Ke")
    cf = cov_fracs(p)
    fx = cf["x"]
    d = fce - fca
    R_int = quantize(p.design.R, p.vars["S"].fmt)
    # c_e in c_a's format, rounded in 32 bits, plus R fits int32 for any c_e
    s_fits = d > 0 and (2**31 >> d) + 1 + abs(R_int) < 2**31 - 1
    # 0 < xs <= 2^30 (acn_recip: x <= 2^31): for any int32 c_e the product lies in [-2^61, (2^31 - 1) 2^30];
    # when both ends, shifted and rounded, fit int32, K_e needs no saturation
    sh = fce + fx - fKe
    ke_free = ((2**31 - 1) * 2**30 + 2 ** (sh - 1)) >> sh <= 2**31 - 1 and (-(2**61) + 2 ** (sh - 1)) >> sh >= -(2**31)
    return s_fits, ke_free, cf


def cov_sums(p: AxisPlan) -> CovSums:
    """The covariance form's predict and update of this view of the plan, decided."""
    t = predict_terms(p)
    pred = {n: _sat(p, *t[n]) for n in ("tr", "tv", "cr", "cv", "ca")}
    for n in DITHERED:
        ft, terms = t[n]
        dz = "dz"
        h = hsum_of(p, ft, terms[1:], dz)
        pred[n] = ("h", terms[0].var, h) if h is not None else ("acc", None, acc_of(ft, terms, dither=dz))
    pred["ce"] = _ce(p, t)
    return CovSums(p, pred, *_update_fits(p))
