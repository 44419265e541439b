"""Predicted error of the generated fixed-point C against the float64 reference.

Two bounds, both sample by sample:

* :func:`worst_case_bound`: holds for any data within the declared ranges (every innovation at its
  range bound, every error pushed through the l1 gains of the closed (a, eps) loop). Rigorous and
  very loose (the bias mode's l1 gain is ~T/Ts); kept for the report.
* :func:`error_bound`: the useful one. It propagates the per-step rounding and gain errors through
  the closed-loop error dynamics of the filter, sample by sample, with the innovation magnitudes
  |y[k]| and the acceleration |a[k]| of a given run (the float64 reference's, for the lockstep
  tests: rigorous for that data), or, without data, with |y[k]| <= 8 sqrt(S[k]) and |a| <= its range
  bound (what a run that follows the model meets with overwhelming probability: P(|y| > 8 sigma) is
  1e-15 per sample for a Gaussian innovation; a trajectory that breaks the model (steps in a) needs
  the data form).

Derivation. Let e = x_C - x_64 (C minus float64) after the update of sample k, in SI units. The C
(see :func:`codegen.emit_c._core_fixed`) does per sample, with K_C = K + dK:

    predict: eps' = eps - (1 - phi)_C (eps_hi - eps_bar_C) + floor       (d_dec: roundings below)
    y_C     = z_C - a' - eps'_hi                                       (z_C = z + dz, eps'_hi: 1/2 LSB)
    update:  a += K_a,C y_C (1/2 LSB);  eps += K_e,C y_C (floor, 1 LSB of eps)
    r, v = Ts u: r += v + Ts^2/2 a + K_r,C y_C;  v += Ts^2 a + K_v,C y_C  (floors, 1 LSB each)

Write s = a + eps (what z observes). Then with Kt = K_a + K_e, e_s^- = e_s - (1 - phi) e_eps + d_dec,
e_eps^- = phi e_eps + d_dec and y_C - y = dz + d_y - e_s^-:

    e_s+   = (1 - Kt) e_s^- + Kt (dz + d_y) + (dK_a + dK_e) y_C + d_a + d_e
    e_eps+ = e_eps^- - K_e e_s^- + K_e (dz + d_y) + dK_e y_C + d_e
    e_a+   = e_s+ - e_eps+
    e_v+   = e_v + Ts^2 e_a + dT2 a + K_v (dz + d_y - e_s^-) + dK_v y_C + 1 LSB
    e_r+   = e_r + e_v + Ts^2/2 e_a + dH2 a + K_r (dz + d_y - e_s^-) + dK_r y_C + 1 or 2 LSB

Taking absolute values term by term gives a linear recursion for the bounds E (E_s, E_eps decay at
the rates |1 - Kt| and ~ phi + |K_e|, so they stay bounded; E_v and E_r accumulate, as u and r have
no feedback), with |y_C| <= |y| + E_s^- + dz + d_y and |a_C| <= |a| + E_a. Skipped samples drop the
update terms. The gain errors dK: gain-schedule form, the exact |K_stored[k] - K[k]| of the
schedule; covariance form, per sample (dc + |K[k]| dS) / R + |K[k]| 2^-23 + 1 LSB of K, where dc and
dS, the errors of the carried c = P H' and of S, are taken as CONTRACTION_LSB of their formats (the
update contracts c by R / S every sample, so their rounding errors do not accumulate; asserted from
that argument and checked by the lockstep tests, not derived term by term). The covariance form
never rounds a gain on its own: it adds c_i w with w = y / S rounded once (codegen.emit_c._gains_cov),
which is K_i (y + S dw): the rounding dw of w enters like an error of the innovation, S |dw| <= S lsb_w / 2
per sample (the worst-case bound takes S at its range bound).

For a run in the tests, :func:`twin_bound` splits the error exactly: the float64 filter run with the
C's quantized constants (:func:`quantized_twin`) carries the whole deterministic effect of the
constants (signs and all); the recursion above, with the constants taken as exact, bounds what is
left (the per-step roundings, and the covariance form's gain errors). What it catches (mutation
check, 100 Hz vehicle run): the input offset one LSB too high, a product read one bit off, eps_bar
off by 1 %. What it cannot catch: a rounding direction flipped (floor for round in a or in the high
word of eps), the offset one LSB too low, a few LSB of the input scale, or a 1-LSB change of
(1 - phi), eps_bar, Ts^2/2 or a gain slope: each adds at most one LSB a step, which a correct
rounding may also do in the worst case, or (the slow constants) acts on a time scale of T, far
beyond a 30 s test. A bit-exact
Python twin of the integer C would catch those; the bound is the rigorous statement.

What it assumes: the reference is the float64 Kalman filter with the same skips, for both forms;
the gain errors are the generator's stated ones (for the schedule, those of an uninterrupted run;
given a run, :func:`twin_bound` takes the gain-schedule C's gains exactly, skips and the deviation it
carries after them included: :func:`schedule_gain_errors`); the float64 arithmetic itself is exact (its own
error, ~1e-16 relative, is far below every term here).
"""

from __future__ import annotations

import numpy as np

from .ranges import AxisPlan

CONTRACTION_LSB = 16.0
Y_SIGMAS = 8.0


def gain_errors(p: AxisPlan, schedule=None, K: np.ndarray | None = None) -> np.ndarray:
    """Bound of |K_C - K_float64| per gain [r, v, a, e] (C coordinates): over the run, or per sample
    (covariance form, given the float64 gains K (n, 4) of the run)."""
    lsbK = np.array([p.vars["K" + n].fmt.lsb for n in "rvae"])
    if p.form == "gain_schedule":
        return np.asarray(schedule.max_error)
    R = p.design.R
    kmax = np.array([p.vars["K" + n].bound for n in "rvae"]) if K is None else np.abs(K)
    # c_r, c_v, c_a, c_e (and S) in their coarse formats, the LSB they have through and after a gap: away
    # from gaps the C carries them finer (codegen.ranges._plan_fine), so this holds for both (the eps
    # update reads a fine c_e floored to a format no finer than its coarse one: one LSB of that, within
    # the CONTRACTION_LSB taken here)
    dc = CONTRACTION_LSB * np.array([p.vars[n].fmt.lsb for n in ("cr", "cv", "ca", "ce")])
    dS = CONTRACTION_LSB * (p.vars["ca"].fmt.lsb + p.vars["ce"].fmt.lsb)
    # reciprocal: relative 2^-28, and the shifts that align it drop up to 7 of its 30 bits
    return (dc + kmax * dS) / R + kmax * 2.0**-22 + lsbK


def w_injection(p: AxisPlan) -> float:
    """Covariance form: S lsb_w / 2 with S at its range bound, the largest innovation error the
    rounding of w = y / S makes (0 for the gain-schedule form, which has no w)."""
    if p.form != "covariance":
        return 0.0
    return p.vars["S"].bound * p.vars["w"].fmt.lsb / 2


def gains_upto(p: AxisPlan, n: int):
    """The plan's Riccati run with per-sample K, sigma, S for at least the first n samples (the plan
    keeps the first gains.KEEP; a longer run of data gets its own, as long as that data)."""
    from .gains import riccati

    if n <= len(p.gains.K):
        return p.gains
    return riccati(p.design, n)


def _floors(p: AxisPlan) -> tuple[int, int]:
    """How many floors (one LSB each at most) the C's step of r and of v = Ts u takes."""
    v = p.vars
    fy, fr, fv = v["y"].fmt.frac, v["r"].fmt.frac, v["v"].fmt.frac
    if p.form == "covariance":  # r += c_r w, then r += v + Ts^2/2 a; v += c_v w, then v += Ts^2 a
        fw = v["w"].fmt.frac
        fH2, fT2 = p.consts["H2"][1].frac, p.consts["T2"][1].frac
        # c_r, c_v in their coarse or fine formats (codegen.ranges._plan_fine): the more floors of the two
        fcr = max(v[n].fmt.frac for n in ("cr", "cr_f") if n in v)
        fcv = max(v[n].fmt.frac for n in ("cv", "cv_f") if n in v)
        n_r = (fv > fr) + (fcr + fw > fr) + (fH2 + fy > fr)
        return n_r, (fcv + fw > fv) + (fT2 + fy > fv)
    # Ts^2/2 a: in K_r y's accumulator, or onto v before v's shift (its format Q.(fv - fy)), or its own shift
    fH2 = p.consts["H2"][1]
    n_r = (fv > fr) + (v["Kr"].fmt.frac + fy > fr) + (fH2 != v["Kr"].fmt and fH2.frac + fy != fv)
    return n_r, (v["Kv"].fmt.frac + fy > fv) + (p.consts["T2"][1] != v["Kv"].fmt)


def _const_err(p: AxisPlan, name: str) -> float:
    val, fmt = p.consts[name]
    return abs(val - round(val * 2**fmt.frac) / 2**fmt.frac)


def error_bound(
    p: AxisPlan,
    n: int,
    schedule=None,
    *,
    y_abs: np.ndarray | None = None,
    a_abs: np.ndarray | None = None,
    e_dev: float | None = None,
    valid: np.ndarray | None = None,
    exact: bool = False,
    K: np.ndarray | None = None,
    S: np.ndarray | None = None,
    dK: np.ndarray | None = None,
    state: dict | None = None,
) -> np.ndarray:
    """(n, 4) bound of |x_C - x_float64| at every sample k < n: [r m, u m/s, a m/s^2, eps m/s^2].

    y_abs, a_abs: |innovation| and |a| of the float64 run (data form); None: 8 sqrt(S) and the range
    bound of a. e_dev: max |eps - eps_bar| (default: the prior's offset + 8 sigma of eps). valid:
    which samples update (default all). exact: the constants count as exact
    (the bound of the C against :func:`quantized_twin`). K: the gains of the run in C coordinates
    (default: the Kalman gains without skips). S: the innovation variance of the run (covariance form:
    the rounding of w = y / S enters as S lsb_w / 2; default: the S of the Kalman run without skips,
    or S at its range bound when K is given without it). dK: |K_C - K| per sample (n, 4) when known
    exactly (gain schedule after skips: :func:`schedule_gain_errors`); default: the generator's stated
    errors. state: a run in pieces (:func:`_schedule_bound_rows`): the recursion starts from it (its
    "k0" the first sample's index) and leaves its end in it.
    """
    v, d = p.vars, p.design
    Ts, phi = d.Ts, d.phi
    omp = 1.0 - phi
    lsb_y, lsb_e, lsb_r = v["y"].fmt.lsb, v["e"].fmt.lsb, v["r"].fmt.lsb
    g = gains_upto(p, n) if K is None or y_abs is None or e_dev is None else None
    if K is None:
        K = np.asarray(g.K)[:n] * np.array([1.0, Ts, 1.0, 1.0])
    dz_ = p.z_error
    sched_err = None if schedule is None else schedule.errors(n)
    if exact:  # against the quantized twin: constants exact, the input's only error its final rounding
        dz_ = v["z"].fmt.lsb / 2
    if dK is not None:
        dK = np.asarray(dK)[:n]
    elif p.form == "gain_schedule":
        dK = sched_err
    else:
        dK = gain_errors(p, K=K[:n])
    if y_abs is None:
        y_abs = Y_SIGMAS * np.sqrt(np.asarray(g.S)[:n])
    if a_abs is None:
        a_abs = np.full(n, v["a"].bound)
    if valid is None:
        valid = np.ones(n, dtype=bool)
    dz = dz_
    d_y = lsb_y / 2  # eps'_hi rounded
    d_w = np.full(n, w_injection(p))  # covariance form: the rounding of w = y / S, as an innovation error
    if p.form == "covariance" and (S is not None or g is not None):
        d_w = np.asarray(S if S is not None else g.S, dtype=np.float64)[:n] * (v["w"].fmt.lsb / 2)
    d_a = lsb_y / 2  # a += K_a y rounded
    d_e = lsb_e  # eps += K_e y floored
    # decay: eps_hi (1/2 LSB of y) and eps_bar's rounding through (1 - phi), (1 - phi)'s own rounding
    # on |eps - eps_bar| (eps within the range bound), the floor
    e_bar_err = 0.0 if exact else _const_err(p, "EBAR")
    d_omp = 0.0 if exact else _const_err(p, "OMP")
    if e_dev is None:  # |eps - eps_bar|: the prior's offset and 8 sigma of the bias
        e_dev = abs(d.x0[3] - d.eps_mean) + Y_SIGMAS * float(np.asarray(g.sigma)[:n, 3].max())
    d_dec = omp * (lsb_y / 2 + e_bar_err) + d_omp * (e_dev + lsb_y) + lsb_e
    dH2, dT2 = (0.0, 0.0) if exact else (_const_err(p, "H2"), _const_err(p, "T2"))
    # floors of the steps of r and v (_floors)
    n_r_floor, n_v_floor = _floors(p)
    lsb_v = v["v"].fmt.lsb
    H2, T2 = Ts * Ts / 2, Ts * Ts
    Es, Ee = 0.0, lsb_e / 2  # x0: eps0 rounded, a0 = 0 exact
    Ea, Ev, Er = Ee, 0.0, 0.0
    a_prev = 0.0
    k0 = 0
    if state:
        Es, Ee, Ea, Ev, Er, a_prev, k0 = (state[x] for x in ("Es", "Ee", "Ea", "Ev", "Er", "a_prev", "k0"))
    from .gains import bound_loop

    st = [Es, Ee, Ea, Ev, Er, a_prev]
    bp = [omp, phi, d_dec, H2, T2, dH2, dT2, n_r_floor * lsb_r, n_v_floor * lsb_v, dz, d_y, d_a, d_e, Ts]
    vb = np.broadcast_to(np.asarray(valid, dtype=bool), (n,))
    ya, aa = np.broadcast_to(np.asarray(y_abs, dtype=np.float64), (n,)), np.broadcast_to(a_abs, (n,))
    res = bound_loop(k0, bp, np.asarray(K)[:n], np.asarray(dK)[:n], ya, aa, d_w, vb, st)
    if res is not None:  # the same recursion in C, the same doubles (its loop below)
        if state is not None:
            state.update(zip(("Es", "Ee", "Ea", "Ev", "Er", "a_prev"), st, strict=True), k0=k0 + n)
        return res
    out, st = _bound_loop_py(n, k0, bp, K, dK, y_abs, a_abs, d_w, valid, st)
    if state is not None:
        state.update(zip(("Es", "Ee", "Ea", "Ev", "Er", "a_prev"), st, strict=True), k0=k0 + n)
    return out


def _bound_loop_py(n: int, k0: int, bp, K, dK, y_abs, a_abs, d_w, valid, st):
    """:func:`error_bound`'s recursion in Python, where its C twin (gains.bound_loop) is not built:
    (the (n, 4) bounds, the errors at the end [Es, Ee, Ea, Ev, Er, a_prev])."""
    omp, phi, d_dec, H2, T2, dH2, dT2, r_floor, v_floor, dz, d_y, d_a, d_e, Ts = bp
    Es, Ee, Ea, Ev, Er, a_prev = st
    out = np.empty((n, 4))
    Kl, dKl, yl, al, vl = K.tolist(), np.asarray(dK).tolist(), np.asarray(y_abs).tolist(), np.asarray(a_abs), valid
    dwl = d_w.tolist()
    al = al.tolist()
    vl = np.asarray(vl).tolist()
    for k in range(n):
        if k + k0:
            Esm = Es + omp * Ee + d_dec
            Eem = phi * Ee + d_dec
        else:
            Esm, Eem = Es, Ee
        # r and v: the previous posterior a (its error Ea), the constants' rounding on |a|
        a_c = a_prev + Ea
        Er = Er + Ev + H2 * Ea + dH2 * a_c + r_floor
        Ev = Ev + T2 * Ea + dT2 * a_c + v_floor
        if vl[k]:
            kr, kv, ka, ke = Kl[k]
            dkr, dkv, dka, dke = dKl[k]
            inj = dz + d_y + dwl[k]
            yc = yl[k] + Esm + inj
            Es = abs(1.0 - ka - ke) * Esm + abs(ka + ke) * inj + (dka + dke) * yc + d_a + d_e
            Ee = Eem + abs(ke) * (Esm + inj) + dke * yc + d_e
            Ev += abs(kv) * (Esm + inj) + dkv * yc
            Er += abs(kr) * (Esm + inj) + dkr * yc
        else:
            Es, Ee = Esm, Eem
        Ea = Es + Ee
        a_prev = al[k]
        out[k, 0] = Er
        out[k, 1] = Ev / Ts
        out[k, 2] = Ea
        out[k, 3] = Ee
    return out, [Es, Ee, Ea, Ev, Er, a_prev]


def error_bound_rows(p: AxisPlan, n: int, rows, schedule=None) -> np.ndarray:
    """:func:`error_bound` without data (|y| <= 8 sqrt(S), |a| at its range bound, every sample valid)
    at the sorted sample indices ``rows`` < n, (len(rows), 4). Covariance form: a C recursion fed by the
    Riccati sample by sample, so its time is linear in n and its memory does not grow with n (the
    report runs it over the declared run); otherwise, or without a C compiler, error_bound itself."""
    from .gains import _key, bound_rows

    rows = sorted(int(k) for k in rows)
    if p.form == "covariance":
        v, d = p.vars, p.design
        lsb_y, lsb_e, lsb_r, lsb_v = v["y"].fmt.lsb, v["e"].fmt.lsb, v["r"].fmt.lsb, v["v"].fmt.lsb
        omp = 1.0 - d.phi
        # the same numbers error_bound derives (exact=False, no data); keep the two in step
        e_dev = abs(d.x0[3] - d.eps_mean) + Y_SIGMAS * float(p.gains.sigma_max[3]) if n == p.n_run else None
        if e_dev is not None:
            d_dec = omp * (lsb_y / 2 + _const_err(p, "EBAR")) + _const_err(p, "OMP") * (e_dev + lsb_y) + lsb_e
            n_r_floor, n_v_floor = _floors(p)
            lsbK = [v["K" + c].fmt.lsb for c in "rvae"]
            dc = [CONTRACTION_LSB * v[c].fmt.lsb for c in ("cr", "cv", "ca", "ce")]
            dS = CONTRACTION_LSB * (v["ca"].fmt.lsb + v["ce"].fmt.lsb)
            inj = p.z_error + lsb_y / 2
            bp = [omp, d.Ts, inj, lsb_y / 2, lsb_e, d_dec, _const_err(p, "H2"), _const_err(p, "T2")]
            bp += [n_r_floor * lsb_r, n_v_floor * lsb_v, v["a"].bound, Y_SIGMAS, dS, d.R, 2.0**-22, lsb_e / 2]
            out = bound_rows(_key(d), n, np.array(bp + dc + lsbK + [v["w"].fmt.lsb / 2]), rows)
            if out is not None:
                return out
    if p.form == "gain_schedule" and n > len(schedule.head_error):
        return _schedule_bound_rows(p, n, rows, schedule)
    return error_bound(p, n, schedule)[rows]


def _schedule_bound_rows(p: AxisPlan, n: int, rows: list, schedule, chunk: int = 1 << 17) -> np.ndarray:
    """Gain-schedule form: :func:`error_bound` without data over n samples, a chunk at a time (the
    Riccati from the prior at each chunk's start, the schedule's integers replayed there): memory
    O(chunk), whatever n."""
    from .gains import riccati_chunks

    d, Ts = p.design, p.design.Ts
    e_dev = abs(d.x0[3] - d.eps_mean) + Y_SIGMAS * float(p.gains.sigma_max[3])
    lsb = np.array([p.vars["K" + c].fmt.lsb for c in "rvae"])
    scale = np.array([1.0, Ts, 1.0, 1.0])
    a_abs = np.full(chunk, p.vars["a"].bound)
    state: dict = {}
    out = np.empty((len(rows), 4))
    rows_a = np.asarray(rows)
    for k0, K, S in riccati_chunks(d, n, chunk):
        m = len(S)
        Kc = K * scale
        dK = np.abs(schedule.gains_int(k0 + m, k0) * lsb - Kc)
        b = error_bound(
            p, m, schedule, y_abs=Y_SIGMAS * np.sqrt(S), a_abs=a_abs[:m], e_dev=e_dev, K=Kc, dK=dK, state=state
        )
        sel = (rows_a >= k0) & (rows_a < k0 + m)
        out[sel] = b[rows_a[sel] - k0]
    return out


def worst_case_bound(p: AxisPlan, n: int, schedule=None, rows=None) -> np.ndarray:
    """(n, 4) bound for any data within the declared ranges (every |y| at its bound): l1 gains of the
    closed (a, eps) loop carry the per-step injections to a and eps; u and r add theirs up. ``rows``:
    only at those sample indices (len(rows), 4)."""
    v = p.vars
    l1 = p.l1
    ymax = v["y"].bound
    dK = gain_errors(p, schedule)
    Kmax = p.gains.kmax * np.array([1.0, p.design.Ts, 1.0, 1.0])
    lsb_y, lsb_e, lsb_r = v["y"].fmt.lsb, v["e"].fmt.lsb, v["r"].fmt.lsb
    omp = 1.0 - p.design.phi
    d_in = p.z_error + lsb_y / 2 + w_injection(p)
    d_a = lsb_y / 2 + dK[2] * ymax
    d_e = (
        2 * lsb_e
        + omp * (lsb_y / 2 + _const_err(p, "EBAR"))
        + _const_err(p, "OMP") * (v["e"].bound + abs(p.consts["EBAR"][0]))
        + dK[3] * ymax
    )
    Ea = l1.z_a * d_in + l1.a_a * d_a + l1.e_a * d_e
    Ee = l1.z_e * d_in + l1.a_e * d_a + l1.e_e * d_e
    Ts = p.design.Ts
    dv = Ts * Ts * Ea + _const_err(p, "T2") * v["a"].bound + 2 * lsb_r + Kmax[1] * (Ea + Ee + d_in) + dK[1] * ymax
    dr0 = Ts * Ts / 2 * Ea + _const_err(p, "H2") * v["a"].bound + 2 * lsb_r + Kmax[0] * (Ea + Ee + d_in) + dK[0] * ymax
    k = np.arange(1, n + 1, dtype=np.float64) if rows is None else np.asarray(rows, dtype=np.float64) + 1
    out = np.empty((len(k), 4))
    out[:, 0] = k * dr0 + k * (k - 1) / 2 * dv
    out[:, 1] = k * dv / Ts
    out[:, 2] = Ea
    out[:, 3] = Ee
    return out


def quantized_twin(p: AxisPlan, code: np.ndarray | None, z: np.ndarray, valid: np.ndarray, schedule=None):
    """The float64 filter with the C's constants: what the C computes, minus its per-step roundings.

    Same recursion as :func:`codegen.emit_c._core_fixed` in float64 and C coordinates (v = Ts u):
    1 - phi, eps_bar, Ts^2/2, Ts^2 and the input scale and offset as quantized; the gains are the
    float64 Kalman gains of this valid pattern for both forms: what the C's gains should be. Their
    distance to the C's gains is not taken from the run: it is the generator's stated gain error
    (gain schedule: the compression error of an uninterrupted run; covariance: its rounding bound),
    which stays in :func:`error_bound`. So a C whose gains leave the Kalman gains by more than the
    generator states (e.g. a time-indexed schedule that ignored a skip) departs from the bound. Returns (x (n, 4)
    in SI units, |y| (n,), |a| (n,), the gains (n, 4), the innovation variance S (n,) of the same Riccati
    run). ``code``: the raw analog codes (None: use z, the conversion error stays in the bound).
    """
    from .gains import riccati
    from .qformat import dequantize, quantize

    c, v, d = p.consts, p.vars, p.design
    n = len(z)

    def q(name):
        val, fmt = c[name]
        return dequantize(quantize(val, fmt), fmt)

    if code is not None and p.conv_shift >= 0:
        fz = v["z"].fmt.frac
        zq = np.asarray(code, dtype=np.float64) * q("SCALE") + (q("OFFSET") - 2.0 ** -(fz + 1))
    else:
        zq = np.asarray(z, dtype=np.float64)
    omp, ebar, h2, t2 = q("OMP"), q("EBAR"), q("H2"), q("T2")
    g = riccati(d, n, valid)
    K = np.asarray(g.K) * np.array([1.0, d.Ts, 1.0, 1.0])
    r = dequantize(quantize(d.x0[0], v["r"].fmt), v["r"].fmt)
    vv = dequantize(quantize(d.Ts * d.x0[1], v["v"].fmt), v["v"].fmt)
    a = dequantize(quantize(d.x0[2], v["a"].fmt), v["a"].fmt)
    e = dequantize(quantize(d.x0[3], v["e"].fmt), v["e"].fmt)
    out = np.empty((n, 4))
    yabs = np.zeros(n)
    Kl, zl, vl = K.tolist(), zq.tolist(), np.asarray(valid).tolist()
    for k in range(n):
        if k:
            # eps = eps - (1 - phi)(eps - eps_bar)
            e = e - omp * (e - ebar)
        pp = h2 * a
        qq = t2 * a
        if vl[k]:
            kr, kv, ka, ke = Kl[k]
            # y = z - a - eps;  x = x + K y
            y = zl[k] - a - e
            yabs[k] = abs(y)
            pp += kr * y
            qq += kv * y
            a = a + ka * y
            e = e + ke * y
        r = r + vv + pp
        vv = vv + qq
        out[k] = (r, vv / d.Ts, a, e)
    return out, yabs, np.abs(out[:, 2]), K, np.asarray(g.S)


def schedule_gain_errors(p: AxisPlan, schedule, valid: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Gain-schedule form: |K_C[k] - K[k]| (n, 4) exactly, K the float64 Kalman gains of this skip pattern
    (C coordinates): K_C is the schedule's integers, and after a skip the C's own deviation recursion
    (codegen.follow, its integer twin bit for bit, with the C's decisions of when to return)."""
    from .follow import followed_gains, thresholds

    n = len(valid)
    Kc, _ = followed_gains(p, schedule.gains_int(n), valid, thresholds(schedule))
    lsb = np.array([p.vars["K" + c].fmt.lsb for c in "rvae"])
    return np.abs(Kc * lsb - np.asarray(K)[:n])


def d_eps_bar(p: AxisPlan) -> float:
    return p.design.eps_mean


def twin_bound(p: AxisPlan, code, z, valid, x_ref: np.ndarray, schedule=None):
    """The stated bound of |x_C - x_float64| for one run, split into its exact deterministic part and
    a rigorous bound on the rest: |x_twin - x_ref| (the effect of the quantized constants, computed
    exactly, signs and all, with the Kalman gains of the run's skip pattern) + the per-step roundings
    and the generator's stated gain errors of the C propagated through the closed loop
    (:func:`error_bound` with exact constants). ``x_ref``: the float64 Kalman filter on the same input
    (accelnav.estimate.kf.run_filter with the same valid mask), never a filter with the C's gains."""
    x_tw, y_abs, a_abs, K, S = quantized_twin(p, code, z, valid, schedule)
    e_dev = float(np.abs(x_tw[:, 3] - d_eps_bar(p)).max())
    dK = schedule_gain_errors(p, schedule, valid, K) if p.form == "gain_schedule" else None
    b = error_bound(
        p,
        len(z),
        schedule,
        y_abs=y_abs,
        a_abs=a_abs,
        e_dev=e_dev,
        valid=valid,
        exact=code is not None,
        K=K,
        S=S,
        dK=dK,
    )
    return np.abs(x_tw - x_ref) + b, x_tw
