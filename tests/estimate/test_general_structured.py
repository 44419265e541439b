"""Issue 24: the general path's kernel on the packed P with F, H and the smoother gain written out.

The former kernel (full 4x4 products, equilibrated Cholesky per smoother step) is kept as it was in
tests/support/csrc_general_old/ and built here as the oracle. On a run with rests, position fixes, gated
aids (some refused) and invalid samples: the filter is the former one's to the bit (the same operations
minus exact zeros); the smoothed means equal the former ones to 1e-12 of each state's scale. The smoothed
covariances cannot (the former solve is itself off by up to 2e-11 of P_rr's scale), so both kernels'
are measured against the RTS recursion in extended precision over the same filter output: the new one
within 5e-12 of each entry's scale, which the former kernel misses.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from accelnav.estimate import fastsmooth
from accelnav.estimate.kf import position_fix, zero_velocity
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design
from accelnav.native.cbuild import STRICT_FLAGS
from accelnav.native.kernels import SMOOTHER, build

OLD = Path(__file__).resolve().parents[1] / "support" / "csrc_general_old"
FILTER = ("x_prior", "P_prior", "x_post", "P_post")


@pytest.fixture(scope="module")
def old_kernel():
    return build(SMOOTHER, OLD, (*STRICT_FLAGS, "-O3"), "acn_fastsmooth_old")


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


def _both(monkeypatch, old_kernel, d, z, valid, extras, gates):
    new = fastsmooth.smooth_general(d, z, valid=valid, extras=extras, gates=gates)
    with monkeypatch.context() as mp:
        mp.setattr(fastsmooth, "_module", old_kernel)
        old = fastsmooth.smooth_general(d, z, valid=valid, extras=extras, gates=gates)
    return new, old


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


def test_structured_general_kernel_equals_the_former_one(monkeypatch, old_kernel, default_model):
    z, valid, extras, gates = _aided(default_model, 60.0)
    d = axis_design(default_model, 0)
    new, old = _both(monkeypatch, old_kernel, d, z, valid, extras, gates)
    assert new.applied.sum() > 1000 and not new.applied.all()
    np.testing.assert_array_equal(new.applied, old.applied)
    for name in FILTER:
        assert np.all(_err(getattr(new, name), getattr(old, name)) <= 1e-12), name
    assert np.all(_err(new.xs, old.xs) <= 1e-12)
    xs, Ps = _rts_extended(d, new)
    assert np.all(_err(new.xs, xs) <= 1e-12)
    assert np.all(_err(new.Ps, Ps) <= 5e-12)


def test_nearly_singular_prior_takes_the_guarded_fallback(monkeypatch, old_kernel, default_model):
    """r and u collinear to 1e-16 and no aid for 500 samples: the LDL' pivot of u keeps under 1e-12 of
    its diagonal, the former equilibrated Cholesky decides those steps. Neither route is accurate there
    (the prior's condition number is near 1/eps); the new kernel stays within 2x of the former's error."""
    d = axis_design(default_model, 1)
    P0 = np.array(d.P0, dtype=float)
    P0[:2, :2] = 1e9 * np.array([[1.0, 1.0 - 1e-16], [1.0 - 1e-16, 1.0]])
    d = dataclasses.replace(d, P0=P0)
    z, valid, extras, gates = _aided(default_model, 20.0, start=500)
    new, old = _both(monkeypatch, old_kernel, d, z, valid, extras, gates)
    p = new.P_prior[1]
    assert (p[4] - p[1] ** 2 / p[0]) / p[4] < 1e-12  # the u pivot of the prior at sample 1
    for name in FILTER:
        assert np.all(_err(getattr(new, name), getattr(old, name)) <= 1e-12), name
    xs, Ps = _rts_extended(d, new)
    assert np.all(_err(new.xs, xs) <= 2 * _err(old.xs, xs))
    assert np.all(_err(new.Ps, Ps) <= 2 * _err(old.Ps, Ps))
