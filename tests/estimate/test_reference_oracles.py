"""The float64 reference filter and smoother against FilterPy and pykalman, step by step.

Two pitfalls of the oracles (see DESIGN.md) are handled here, not hidden:

* FilterPy's ``rts_smoother`` predicts with F x alone and ignores the forcing
  term b. The oracle runs are therefore made on the shifted problem
  eps~ = eps - (c1 + c2), z~ = z - (c1 + c2), for which b = 0 exactly
  (eps~[k+1] = phi eps~[k]), and shifted back before comparing.
* pykalman's initial_state_mean is the prior of the first sample (no predict
  before the first update), which is our convention too; FilterPy's batch
  would predict first, so its lockstep run here updates first at k = 0.

Agreement is asserted at every step for every state: |ours - oracle| <=
1e-9 (|oracle| + sigma) where sigma is the state's own standard deviation,
and for covariances 1e-9 (|P_ij| + sqrt(P_ii P_jj)).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_states
from filterpy.kalman import KalmanFilter as FilterPyKF
from pykalman import KalmanFilter as PyKalmanKF

from accelnav.estimate.kf import position_fix, rts_smooth, run_filter, zero_velocity
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design

RTOL = 1e-9
SCENARIOS = [("stationary", 11), ("stop_and_go", 12), ("vehicle", 13), ("shock", 14)]
DURATION_S = 30.0


def _filterpy_lockstep(d, z, valid, extras=()):
    """FilterPy on the shifted problem, one predict/update at a time; returns posteriors and smoothed."""
    mu = d.eps_mean
    shift = np.array([0.0, 0.0, 0.0, mu])
    kf = FilterPyKF(dim_x=4, dim_z=1)
    kf.x = (d.x0 - shift).reshape(4, 1)
    kf.P = np.array(d.P0)
    kf.F = np.array(d.F)
    kf.Q = np.array(d.Q)
    kf.H = np.array(d.H)
    kf.R = np.array([[d.R]])
    by_k = {}
    for m in extras:
        by_k.setdefault(m.k, []).append(m)
    n = len(z)
    xs = np.empty((n, 4))
    Ps = np.empty((n, 4, 4))
    for k in range(n):
        if k > 0:
            kf.predict()
        if valid[k]:
            kf.update(np.array([[z[k] - mu]]))
        for m in by_k.get(k, ()):
            h = np.array([m.h])
            kf.update(np.array([[m.z - h[0] @ shift]]), R=np.array([[m.R]]), H=h)
        xs[k] = kf.x[:, 0]
        Ps[k] = kf.P
    xsm, Psm, _, _ = kf.rts_smoother(xs.reshape(n, 4, 1), Ps)
    return xs + shift, Ps, xsm.reshape(n, 4) + shift, Psm


@pytest.mark.parametrize("scenario,seed", SCENARIOS)
def test_filter_and_smoother_match_filterpy_every_step(model, scenario, seed):
    run = simulate(model, scenario, DURATION_S, seed)
    for j, name in enumerate(run.axis_names):
        d = axis_design(model, j)
        z, valid = run.accel[:, j], ~run.clipped[:, j]
        f = run_filter(d, z, valid=valid)
        s = rts_smooth(d, f)
        x_ref, P_ref, xs_ref, Ps_ref = _filterpy_lockstep(d, z, valid)
        assert_states(f.x_post, f.P_post, x_ref, P_ref, RTOL, f"{scenario}/{name} filter")
        assert_states(s.x, s.P, xs_ref, Ps_ref, RTOL, f"{scenario}/{name} smoother")
    if scenario == "shock" and model.sensor.kind == "analog":
        assert run.clipped.any(), "the shock scenario must exercise predict-only samples"


@pytest.mark.parametrize("scenario,seed", SCENARIOS[:3])
def test_filter_and_smoother_match_pykalman_every_step(model, scenario, seed):
    run = simulate(model, scenario, 20.0, seed)
    d = axis_design(model, 0)
    z, valid = run.accel[:, 0], ~run.clipped[:, 0]
    valid = valid.copy()
    valid[100:130] = False  # a gap of missing samples: predict only
    f = run_filter(d, z, valid=valid)
    s = rts_smooth(d, f)
    pk = PyKalmanKF(
        transition_matrices=np.array(d.F),
        observation_matrices=np.array(d.H),
        transition_covariance=np.array(d.Q),
        observation_covariance=np.array([[d.R]]),
        transition_offsets=np.array(d.b),  # pykalman applies b in both passes: no shift needed
        observation_offsets=np.zeros(1),
        initial_state_mean=np.array(d.x0),
        initial_state_covariance=np.array(d.P0),
    )
    obs = np.ma.masked_array(z.reshape(-1, 1), mask=~valid.reshape(-1, 1))
    x_ref, P_ref = pk.filter(obs)
    xs_ref, Ps_ref = pk.smooth(obs)
    assert_states(f.x_post, f.P_post, x_ref, P_ref, RTOL, f"{scenario} filter vs pykalman")
    assert_states(s.x, s.P, xs_ref, Ps_ref, RTOL, f"{scenario} smoother vs pykalman")


def test_position_fixes_and_zero_velocity_match_filterpy(default_model):
    run = simulate(default_model, "stop_and_go", DURATION_S, 21)
    d = axis_design(default_model, 0)
    z, valid = run.accel[:, 0], ~run.clipped[:, 0]
    rng = np.random.default_rng(5)
    extras = [position_fix(k, run.r[k, 0] + rng.normal(0, 0.5), 0.5) for k in range(0, len(z), 700)]
    extras += [zero_velocity(k, 0.01) for k in np.flatnonzero(run.u[:, 0] == 0)[::50]]
    extras.append(position_fix(1234, run.r[1234, 0], 0.2))
    extras.append(zero_velocity(1234, 0.05))  # two extras on one sample, after its z update
    f = run_filter(d, z, valid=valid, extras=extras)
    s = rts_smooth(d, f)
    x_ref, P_ref, xs_ref, Ps_ref = _filterpy_lockstep(d, z, valid, extras)
    assert_states(f.x_post, f.P_post, x_ref, P_ref, RTOL, "aided filter")
    assert_states(s.x, s.P, xs_ref, Ps_ref, RTOL, "aided smoother")
    # and the aiding did something: the fixes pin the position
    plain = run_filter(d, z, valid=valid)
    assert np.sqrt(f.P_post[-1, 0, 0]) < 0.1 * np.sqrt(plain.P_post[-1, 0, 0])


def test_prior_and_posterior_conventions(default_model):
    d = axis_design(default_model, 0)
    z = np.full(5, 0.3)
    valid = np.array([True, False, True, True, True])
    f = run_filter(d, z, valid=valid)
    assert np.array_equal(f.x_prior[0], d.x0) and np.array_equal(f.P_prior[0], d.P0)
    # a predict-only sample keeps its prior as its posterior
    assert np.array_equal(f.x_post[1], f.x_prior[1]) and np.isnan(f.y[1])
    # the prior of k+1 is F x_post[k] + b
    assert np.allclose(f.x_prior[3], d.F @ f.x_post[2] + d.b, rtol=0, atol=1e-15)
    # the smoother's last sample is the filter's
    s = rts_smooth(d, f)
    assert np.array_equal(s.x[-1], f.x_post[-1])


def test_extra_measurement_outside_run_is_refused(default_model):
    d = axis_design(default_model, 0)
    with pytest.raises(ValueError, match="outside 0..9"):
        run_filter(d, np.zeros(10), extras=[position_fix(10, 0.0, 1.0)])
