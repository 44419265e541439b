"""Predicted error of the generated fixed-point C against the float64 reference.

Every rounding of the C is an injection of at most half an LSB of its target
format; gain errors inject |dK| |y| with |y| <= the bound of y. Injections
reach a and eps through the closed (a, eps) loop, whose l1 gains are computed
in :mod:`codegen.ranges` (an input-like error enters through K; a push into a;
a push into eps, which the slow bias mode amplifies by ~T/Ts). u and r have
no feedback: their bounds add up every step (linear in k for u, quadratic for
r). The bound therefore holds sample by sample for any data within the
declared ranges, and is pessimistic for ordinary data (|y| is typically 1e-4
of its bound): the lockstep tests also check the much tighter 1e-3 sigma.

Gain errors: gain-schedule form, the exact compression error of the schedule
(max over the run) plus the gain's rounding; covariance form, every carried
c = P H' entry contracts by R/S per update, so its rounding error stays
below CONTRACTION_LSB of its format; dK_i <= (dc_i + |K_i| dS) / R.
"""

from __future__ import annotations

import numpy as np

from .ranges import AxisPlan

CONTRACTION_LSB = 16.0


def gain_errors(p: AxisPlan, schedule=None) -> np.ndarray:
    """Bound of |K_C - K_float64| per gain [r, v, a, e] (C coordinates)."""
    lsbK = np.array([p.vars["K" + n].fmt.lsb for n in "rvae"])
    if p.form == "gain_schedule":
        return np.asarray(schedule.error.max(0)) + lsbK
    R = p.design.R
    kmax = np.array([p.vars["K" + n].bound for n in "rvae"])
    dc = CONTRACTION_LSB * np.array([p.vars[n].fmt.lsb for n in ("cr", "cv", "ca", "ce")])
    dS = CONTRACTION_LSB * (p.vars["ca"].fmt.lsb + p.vars["ce"].fmt.lsb)
    # reciprocal: relative 2^-28
    return (dc + kmax * dS) / R + kmax * 2.0**-28 + lsbK


def error_bound(p: AxisPlan, n: int, schedule=None) -> np.ndarray:
    """(n, 4) bound of |x_C - x_float64| at every sample k < n: [r m, u m/s, a m/s^2, eps m/s^2]."""
    v = p.vars
    l1 = p.l1
    half = {k: x.fmt.lsb / 2 for k, x in v.items()}
    ymax = v["y"].bound
    dK = gain_errors(p, schedule)
    Kmax = np.abs(p.gains.K).max(0) * np.array([1.0, p.design.Ts, 1.0, 1.0])
    c = p.consts
    # input-like: conversion error and the rounding of y
    d_in = p.z_error + half["y"]
    # direct pushes into a (rounding of K_a y, gain error) and eps (roundings, phi and b constants, gain error)
    d_a = half["a"] + dK[2] * ymax
    omp_q = abs(c["OMP"][0] - round(c["OMP"][0] * 2 ** c["OMP"][1].frac) / 2 ** c["OMP"][1].frac)
    # the decay (1 - phi) eps uses the high word of eps: truncation below 2^-(frac-32)
    d_e = 3 * half["e"] + omp_q * v["e"].bound + c["OMP"][0] * 2.0 ** -(v["e"].fmt.frac - 32) + dK[3] * ymax
    Ea = l1.z_a * d_in + l1.a_a * d_a + l1.e_a * d_e
    Ee = l1.z_e * d_in + l1.a_e * d_a + l1.e_e * d_e
    Ts = p.design.Ts
    q = lambda nm: c[nm][1].lsb / 2  # noqa: E731
    # v = Ts u per step: Ts^2 a (error of a, of the constant, rounding), K_v y (error of y, of K_v), clamps exact
    dv = (Ts * Ts) * Ea + q("T2") * v["a"].bound + 2 * half["v"] + Kmax[1] * (Ea + Ee + d_in) + dK[1] * ymax
    # r per step: the v error so far, Ts^2/2 a, K_r y
    dr0 = (Ts * Ts / 2) * Ea + q("H2") * v["a"].bound + 3 * half["r"] + Kmax[0] * (Ea + Ee + d_in) + dK[0] * ymax
    k = np.arange(1, n + 1, dtype=np.float64)
    Ev = k * dv
    Er = k * dr0 + k * (k - 1) / 2 * dv
    out = np.empty((n, 4))
    out[:, 0] = Er
    out[:, 1] = Ev / Ts + half["u_out"]
    out[:, 2] = Ea
    out[:, 3] = Ee
    return out
