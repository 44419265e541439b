"""Issue 24: the general path's kernel on the packed P with F, H and the smoother gain written out.

Oracles independent of the kernel: the filter is the textbook one written out here in float64 numpy
(predict, the acceleration update, then each aid in the given order, gated aids applied iff
y^2 <= gate S), which the kernel must follow to 1e-10 of each state's scale with the same aids applied;
the smoother is the RTS recursion in extended precision over the kernel's own filter output, which the
means must meet to 1e-12 and the covariances to 5e-12 of each entry's scale (the former kernel, a full
4x4 equilibrated Cholesky per step, missed that: 1.4e-11 on P_rr's scale).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from accelnav.estimate import fastsmooth
from accelnav.estimate.kf import position_fix, update, zero_velocity
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design

FILTER = ("x_prior", "P_prior", "x_post", "P_post")
# the former kernel's error on the nearly singular case (largest over the columns, in units of each
# column's scale, against the extended-precision RTS), measured beside the new one when it was retired
FORMER_SINGULAR_ERR = {"xs": 2.7e-4, "Ps": 1.1e-2}


def _aided(model, seconds: float, start: int = 0):
    run = simulate(model, "stop_and_go", seconds, seed=3).to_arrays()
    n = len(run["t"])
    z = run["accel"][:, 0].copy()
    valid = np.ones(n, dtype=bool)
    valid[np.random.default_rng(3).integers(0, n, n // 20)] = False  # scattered invalid samples
    valid[n // 2 : n // 2 + 400] = False  # and a gap: pure predictions
    rest = np.flatnonzero(np.abs(run["u"][:, 0]) < 1e-9)
    extras = [zero_velocity(int(k), 2e-3) for k in rest[rest >= start]]
    extras += [position_fix(k, float(run["r"][k, 0]) + 0.2, 0.3) for k in range(start + 200, n, 900)]
    gates = [9.0 if i % 3 == 0 else 0.0 for i in range(len(extras))]  # some aids gated, most not
    extras += [position_fix(k, float(run["r"][k, 0]) + 50.0, 0.3) for k in range(start + 650, n, 1300)]
    gates += [9.0] * (len(extras) - len(gates))  # outliers the gate refuses
    return z, valid, extras, gates


def _reference_filter(d, z, valid, extras, gates):
    """The filter written out in float64: (x_prior, P_prior packed, x_post, P_post packed, applied)."""
    n = len(z)
    order = np.argsort([m.k for m in extras], kind="stable")
    by_k: dict[int, list[int]] = {}
    for i in order:
        by_k.setdefault(int(extras[i].k), []).append(int(i))
    F, Q, b, H, R = (np.asarray(a, dtype=np.float64) for a in (d.F, d.Q, d.b, d.H[0], d.R))
    x, P = np.array(d.x0, dtype=np.float64), np.array(d.P0, dtype=np.float64)
    xp, Pp, xf, Pf = np.empty((n, 4)), np.empty((n, 4, 4)), np.empty((n, 4)), np.empty((n, 4, 4))
    applied = np.zeros(len(extras), dtype=bool)
    for k in range(n):
        if k > 0:
            x, P = F @ x + b, F @ P @ F.T + Q
        xp[k], Pp[k] = x, P
        if valid[k]:
            x, P, _, _ = update(x, P, H, z[k], float(R))
        for i in by_k.get(k, ()):
            m, h = extras[i], np.asarray(extras[i].h, dtype=np.float64)
            y, S = m.z - h @ x, h @ P @ h + m.R
            if gates[i] > 0 and y * y > gates[i] * S:
                continue
            x, P, _, _ = update(x, P, h, m.z, m.R)
            applied[i] = True
        xf[k], Pf[k] = x, P
    return {"x_prior": xp, "P_prior": fastsmooth.pack(Pp), "x_post": xf, "P_post": fastsmooth.pack(Pf)}, applied


def _rts_extended(d, f) -> tuple[np.ndarray, np.ndarray]:
    """C = Pf F' inv(Pp), xs = xf + C (xs1 - xp1), Ps = Pf + C (Ps1 - Pp1) C', all in np.longdouble."""
    if np.finfo(np.longdouble).eps > 1e-18:
        pytest.skip("np.longdouble is no wider than float64 here: no extended-precision oracle")
    L = np.longdouble
    F = np.asarray(d.F, dtype=L)
    Pp, Pf = fastsmooth.unpack(f.P_prior).astype(L), fastsmooth.unpack(f.P_post).astype(L)
    xp, xf = f.x_prior.astype(L), f.x_post.astype(L)
    n = len(xf)
    xs, Ps = xf.copy(), Pf.copy()
    for k in range(n - 2, -1, -1):
        A, B = Pp[k + 1].copy(), F @ Pf[k]
        for i in range(4):  # Gaussian elimination, partial pivoting (numpy's solve has no longdouble)
            p = i + int(np.argmax(np.abs(A[i:, i])))
            A[[i, p]], B[[i, p]] = A[[p, i]], B[[p, i]]
            for r in range(i + 1, 4):
                g = A[r, i] / A[i, i]
                A[r, i:] -= g * A[i, i:]
                B[r] -= g * B[i]
        X = np.empty_like(B)
        for i in range(3, -1, -1):
            X[i] = (B[i] - A[i, i + 1 :] @ X[i + 1 :]) / A[i, i]
        C = X.T
        xs[k] = xf[k] + C @ (xs[k + 1] - xp[k + 1])
        Ps[k] = Pf[k] + C @ (Ps[k + 1] - Pp[k + 1]) @ C.T
    return xs, fastsmooth.pack(Ps)


def _err(got: np.ndarray, want: np.ndarray) -> np.ndarray:
    """Largest error of each column, in units of that column's largest magnitude."""
    return (np.max(np.abs(got - want), axis=0) / np.max(np.abs(want), axis=0)).astype(float)


def test_structured_general_kernel_follows_the_written_out_filter_and_rts(default_model):
    z, valid, extras, gates = _aided(default_model, 60.0)
    d = axis_design(default_model, 0)
    new = fastsmooth.smooth_general(d, z, valid=valid, extras=extras, gates=gates)
    ref, applied = _reference_filter(d, z, valid, extras, gates)
    assert new.applied.sum() > 1000 and not new.applied.all()
    np.testing.assert_array_equal(new.applied, applied)
    for name in FILTER:
        assert np.all(_err(getattr(new, name), ref[name]) <= 1e-10), name
    xs, Ps = _rts_extended(d, new)
    assert np.all(_err(new.xs, xs) <= 1e-12)
    assert np.all(_err(new.Ps, Ps) <= 5e-12)


def test_nearly_singular_prior_takes_the_guarded_fallback(default_model):
    """r and u collinear to 1e-16 and no aid for 500 samples: the LDL' pivot of u keeps under 1e-12 of
    its diagonal, the guarded equilibrated Cholesky decides those steps. Neither that nor any float64
    route is accurate there (the prior's condition number is near 1/eps): the bound is twice the former
    kernel's error on this case."""
    d = axis_design(default_model, 1)
    P0 = np.array(d.P0, dtype=float)
    P0[:2, :2] = 1e9 * np.array([[1.0, 1.0 - 1e-16], [1.0 - 1e-16, 1.0]])
    d = dataclasses.replace(d, P0=P0)
    z, valid, extras, gates = _aided(default_model, 20.0, start=500)
    new = fastsmooth.smooth_general(d, z, valid=valid, extras=extras, gates=gates)
    p = new.P_prior[1]
    assert (p[4] - p[1] ** 2 / p[0]) / p[4] < 1e-12  # the u pivot of the prior at sample 1
    xs, Ps = _rts_extended(d, new)
    assert _err(new.xs, xs).max() <= 2 * FORMER_SINGULAR_ERR["xs"]
    assert _err(new.Ps, Ps).max() <= 2 * FORMER_SINGULAR_ERR["Ps"]


def _rts_step_float64(d, xf, pf, xp1, pp1, xs1, ps1):
    """One RTS step for every sample at once in float64 numpy, written as the kernel's rts_step takes it: B = F Pf,
    the smoother gain by the unrolled LDL' of the prior, each substitution over B's four columns, then the mean and
    the covariance; every sum left to right as the C writes it. (xs, Ps packed, where the LDL' pivots pass the
    kernel's guard: the guarded fallback decides the others.)"""
    F = np.asarray(d.F, dtype=np.float64)
    f01, f02, f12, phi = F[0, 1], F[0, 2], F[1, 2], F[3, 3]
    P = fastsmooth.unpack(pf)
    B0, B1, B2, B3 = P[:, 0] + f01 * P[:, 1] + f02 * P[:, 2], P[:, 1] + f12 * P[:, 2], P[:, 2], phi * P[:, 3]
    rr, ru, ra, re, uu, ua, ue, aa, ae, ee = (pp1[:, i : i + 1] for i in range(10))
    i0 = 1.0 / rr
    l10, l20, l30 = ru * i0, ra * i0, re * i0
    d1 = uu - l10 * ru
    i1 = 1.0 / d1
    t21, t31 = ua - l20 * ru, ue - l30 * ru
    l21, l31 = t21 * i1, t31 * i1
    d2 = aa - l20 * ra - l21 * t21
    i2 = 1.0 / d2
    t32 = ae - l30 * ra - l31 * t21
    l32 = t32 * i2
    d3 = ee - l30 * re - l31 * t31 - l32 * t32
    i3 = 1.0 / d3
    ok = ((rr > 0) & (d1 > 1e-12 * uu) & (d2 > 1e-12 * aa) & (d3 > 1e-12 * ee))[:, 0]
    y1 = B1 - l10 * B0
    y2 = B2 - l20 * B0 - l21 * y1
    y3 = B3 - l30 * B0 - l31 * y1 - l32 * y2
    X3 = y3 * i3
    X2 = y2 * i2 - l32 * X3
    X1 = y1 * i1 - l21 * X2 - l31 * X3
    X0 = B0 * i0 - l10 * X1 - l20 * X2 - l30 * X3  # X_l[:, i] = C[i][l]
    dx = xs1 - xp1
    xs = xf + X0 * dx[:, 0:1] + X1 * dx[:, 1:2] + X2 * dx[:, 2:3] + X3 * dx[:, 3:4]
    D = fastsmooth.unpack(ps1 - pp1)
    Ps = np.empty((len(xf), 4, 4))
    for i in range(4):
        T = (
            X0[:, i : i + 1] * D[:, 0]
            + X1[:, i : i + 1] * D[:, 1]
            + X2[:, i : i + 1] * D[:, 2]
            + X3[:, i : i + 1] * D[:, 3]
        )
        Ps[:, i] = T[:, 0:1] * X0 + T[:, 1:2] * X1 + T[:, 2:3] * X2 + T[:, 3:4] * X3
    return ok, xs, pf + fastsmooth.pack(Ps)


def test_the_smoother_step_is_the_written_out_float64_step_bit_for_bit(default_model):
    """Each backward step of the kernel (rts_step) from its own filter output and the next smoothed sample is the
    float64 step written out above, to the bit: the kernel's operations and their order are pinned, so a rewrite
    that claims the same doubles (the transposed gain, the rows two at a time) is held to it. Aided data: rests,
    fixes, gated aids rejected, invalid samples and a gap."""
    z, valid, extras, gates = _aided(default_model, 60.0)
    d = axis_design(default_model, 0)
    g = fastsmooth.smooth_general(d, z, valid=valid, extras=extras, gates=gates)
    ok, xs, Ps = _rts_step_float64(d, g.x_post[:-1], g.P_post[:-1], g.x_prior[1:], g.P_prior[1:], g.xs[1:], g.Ps[1:])
    assert ok.mean() > 0.99  # the guarded fallback is the rare case (and has a test of its own above)
    np.testing.assert_array_equal(xs[ok], g.xs[:-1][ok])
    np.testing.assert_array_equal(Ps[ok], g.Ps[:-1][ok])
