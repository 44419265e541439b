"""The compiled filter + smoother (accelnav.estimate.fastsmooth) against the float64 reference, every sample.

Agreement is asserted as in test_reference_oracles: |ours - ref| <= 1e-9 (|ref| + sigma)
for states, 1e-9 (|P_ij| + sqrt(P_ii P_jj)) for covariances, for the filter's
priors and posteriors and for the smoother, on both paths.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_states

from accelnav.estimate import fastsmooth as fs
from accelnav.estimate.kf import position_fix, rts_smooth, run_filter, zero_velocity
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design

RTOL = 1e-9


def _assert_all(res: fs.AxisSmooth, f, s, what):
    assert_states(res.x_prior, fs.unpack(res.P_prior), f.x_prior, f.P_prior, RTOL, f"{what} prior")
    assert_states(res.x_post, fs.unpack(res.P_post), f.x_post, f.P_post, RTOL, f"{what} filter")
    assert_states(res.xs, fs.unpack(res.Ps), s.x, s.P, RTOL, f"{what} smoother")


@pytest.mark.parametrize("scenario,seed", [("stop_and_go", 31), ("shock", 32), ("vehicle", 33)])
def test_plain_path_matches_reference(model, scenario, seed):
    run = simulate(model, scenario, 20.0, seed)
    for j in range(run.n_axes):
        d = axis_design(model, j)
        z, valid = run.accel[:, j], ~run.clipped[:, j].copy()
        if j == 0:
            valid[500:540] = False  # a gap: predict only, the gains follow the mask
        res = fs.smooth(d, z, valid=valid)
        assert res.path == "plain"
        f = run_filter(d, z, valid=valid)
        _assert_all(res, f, rts_smooth(d, f), f"{scenario}/{j} plain")
        # the smoother's last sample is the filter's, exactly
        assert np.array_equal(res.xs[-1], res.x_post[-1]) and np.array_equal(res.Ps[-1], res.P_post[-1])
    if scenario == "shock" and model.sensor.kind == "analog":
        assert run.clipped.any()


def test_plain_path_closed_form_r_u(default_model):
    """Smoothed r, u are the closed-form integrals of smoothed a (module docstring, point 3)."""
    d = axis_design(default_model, 0)
    run = simulate(default_model, "sinusoid", 10.0, 3)
    res = fs.smooth_plain(d, run.accel[:, 0])
    Q = np.asarray(d.Q)
    gr, gu = Q[0, 2] / Q[2, 2], Q[1, 2] / Q[2, 2]
    assert gr == pytest.approx(d.Ts**2 / 6, rel=1e-12) and gu == pytest.approx(d.Ts / 2, rel=1e-12)
    r, u, a = res.xs[:, 0], res.xs[:, 1], res.xs[:, 2]
    du = u[1:] - (u[:-1] + d.Ts * (a[:-1] + a[1:]) / 2)
    dr = r[1:] - (r[:-1] + d.Ts * u[:-1] + d.Ts**2 * (a[:-1] / 3 + a[1:] / 6))
    sd = fs.packed_sd(res.Ps)
    assert np.all(np.abs(du[:-1]) <= 1e-12 * (np.abs(u[1:-1]) + sd[1:-1, 1]))
    assert np.all(np.abs(dr[:-1]) <= 1e-12 * (np.abs(r[1:-1]) + sd[1:-1, 0]))


def _extras(run, j, rng):
    n = len(run.t)
    ex = [position_fix(k, run.r[k, j] + rng.normal(0, 0.3), 0.3) for k in range(150, n, 600)]
    ex += [zero_velocity(int(k), 0.01) for k in np.flatnonzero(run.u[:, j] == 0)[::40]]
    ex += [position_fix(777, run.r[777, j], 0.1), zero_velocity(777, 0.05)]  # two on one sample, in order
    return ex


@pytest.mark.parametrize("scenario,seed", [("stop_and_go", 41), ("shock", 42)])
def test_general_path_matches_reference_with_fixes_and_zupt(model, scenario, seed):
    run = simulate(model, scenario, 20.0, seed)
    rng = np.random.default_rng(seed)
    for j in range(run.n_axes):
        d = axis_design(model, j)
        z, valid = run.accel[:, j], ~run.clipped[:, j]
        ex = _extras(run, j, rng)
        res = fs.smooth(d, z, valid=valid, extras=ex)
        assert res.path == "general" and res.applied.all()
        f = run_filter(d, z, valid=valid, extras=ex)
        _assert_all(res, f, rts_smooth(d, f), f"{scenario}/{j} general")


def test_general_path_without_extras_matches_plain(default_model):
    run = simulate(default_model, "vehicle", 20.0, 5)
    d = axis_design(default_model, 1)
    g = fs.smooth_general(d, run.accel[:, 1])
    p = fs.smooth_plain(d, run.accel[:, 1])
    assert_states(g.xs, fs.unpack(g.Ps), p.xs, fs.unpack(p.Ps), RTOL, "general vs plain")
    assert_states(g.x_post, fs.unpack(g.P_post), p.x_post, fs.unpack(p.P_post), RTOL, "general vs plain filter")


def test_gated_extras_and_reference_rerun(default_model):
    """A gate refuses a zero-velocity update while moving; the reference rerun with the applied ones agrees."""
    run = simulate(default_model, "stop_and_go", 20.0, 8)
    d = axis_design(default_model, 0)
    z = run.accel[:, 0]
    moving = np.flatnonzero(np.abs(run.u[:, 0]) > 0.5)[::25]
    resting = np.flatnonzero(run.u[:, 0] == 0)[::25]
    assert len(moving) > 5 and len(resting) > 5
    ex = [zero_velocity(int(k), 0.01) for k in np.concatenate([moving, resting])]
    res = fs.smooth(d, z, extras=ex, gates=[16.0] * len(ex))
    n_mov = len(moving)
    assert not res.applied[:n_mov].any(), "a zero-velocity update during motion passed the gate"
    assert res.applied[n_mov:].mean() > 0.9
    kept = [m for m, a in zip(ex, res.applied, strict=True) if a]
    f = run_filter(d, z, extras=kept)
    _assert_all(res, f, rts_smooth(d, f), "gated")
    ungated = fs.smooth(d, z, extras=ex)
    assert ungated.applied.all()


def test_prior_with_cross_terms_takes_the_general_path(default_model):
    from dataclasses import replace

    d = axis_design(default_model, 0)
    P0 = np.diag([0.5, 0.2, 0.05, 0.05]) ** 2
    P0[0, 2] = P0[2, 0] = 0.3 * 0.5 * 0.05
    d2 = replace(d, P0=P0)
    z = simulate(default_model, "sinusoid", 5.0, 2).accel[:, 0]
    res = fs.smooth(d2, z)
    assert res.path == "general"
    f = run_filter(d2, z)
    _assert_all(res, f, rts_smooth(d2, f), "cross-term prior")
    with pytest.raises(ValueError, match="cross terms"):
        fs.smooth_plain(d2, z)


def test_gain_cache_keys_and_disk(default_model, tmp_path):
    d = axis_design(default_model, 0)
    fs.clear_gain_cache()
    g1 = fs.plain_gains(d, 300)
    assert fs.plain_gains(d, 300) is g1
    mask = np.ones(300, dtype=bool)
    assert fs.plain_gains(d, 300, mask) is g1  # an all-true mask is no mask
    mask[10] = False
    g2 = fs.plain_gains(d, 300, mask)
    assert g2.key != g1.key and g2.K[10].tolist() == [0.0] * 4
    assert fs.plain_gains(axis_design(default_model, 1), 300).key != g1.key
    fs.clear_gain_cache()
    g3 = fs.plain_gains(d, 300, cache_dir=tmp_path)
    assert (tmp_path / f"gains-{g3.key}.npz").is_file()
    fs.clear_gain_cache()
    g4 = fs.plain_gains(d, 300, cache_dir=tmp_path)
    assert g4 is not g3 and np.array_equal(g4.Cs, g3.Cs) and np.array_equal(g4.Ps, g1.Ps)


def test_refusals(default_model):
    d = axis_design(default_model, 0)
    with pytest.raises(ValueError, match="outside 0..9"):
        fs.smooth(d, np.zeros(10), extras=[position_fix(10, 0.0, 1.0)])
    with pytest.raises(ValueError, match="variance"):
        fs.smooth(d, np.zeros(10), extras=[position_fix(3, 0.0, 0.0)])
    with pytest.raises(ValueError, match="valid"):
        fs.smooth(d, np.zeros(10), valid=np.ones(9, dtype=bool))


def test_single_sample_and_nan_input(default_model):
    d = axis_design(default_model, 0)
    for z in (np.array([0.2]), np.array([0.1, np.nan, 0.3, 0.2])):
        res = fs.smooth(d, z)
        f = run_filter(d, z)
        _assert_all(res, f, rts_smooth(d, f), f"n={len(z)}")


def test_disk_gains_of_a_short_run_after_a_long_one(default_model, tmp_path):
    """The steady rows a long run settled on (held in memory, or in the cache folder) are more rows than a short
    run has: the short run's gains keep only its own, so their disk entry stays within its kind's size limit and
    reads back (it raised "built ... bytes, more than the ..." once a long run had left its rows)."""
    d = axis_design(default_model, 0)
    st = fs.steady_gains(d, 10_000_000)
    assert st is not None and st.settled and len(st.rows) > 300, "settled in fewer rows than the short run: no test"
    fs.clear_gain_cache()
    g = fs.plain_gains(d, 300, cache_dir=tmp_path)
    assert len(g.K) <= 300 and (tmp_path / f"gains-{g.key}.npz").is_file()
    fs.clear_gain_cache()
    again = fs.plain_gains(d, 300, cache_dir=tmp_path)
    ref = fs.plain_gains(d, 300, steady=False)
    np.testing.assert_array_equal(again.K, g.K)
    np.testing.assert_allclose(again.Ps, ref.Ps, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(again.K, ref.K[: len(again.K)], rtol=1e-12, atol=1e-15)
