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
