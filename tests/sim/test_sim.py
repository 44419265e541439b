"""The simulator (hil_sim): truth trajectories, bias, noise, read-out, run files.

Statistical checks state their tolerance in standard errors (SE) of the
estimate and use 4 SE unless noted: with seeded data they are deterministic,
and a correct simulator passes them with a wide margin. Standard errors of
means over correlated samples come from batch means (50 contiguous batches).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.stats import norm

from accelnav.hil_sim.sim.sensor import AXIS_GAIN, JITTER_FRACTION, SimRun, simulate
from accelnav.hil_sim.sim.trajectories import SCENARIOS, truth
from accelnav.model.design import input_conversion
from accelnav.model.load import DEFAULT_MODEL, G0, Model, load_model, loads_model

N_SE = 4.0

DUTY_TOML = """
[model]
name = "adxl202_like"
description = "ADXL202-style duty-cycle part, timer capture at 1 MHz, 100 Hz"

[sensor]
kind = "duty_cycle"
part = "ADXL202"
range_g = 2.0
noise_density_g_rthz = 200.0e-6
bandwidth_hz = 50.0

[sensor.duty_cycle]
timer_clock_hz = 1.0e6
t2_period_s = 0.005
zero_g_duty = 0.5
duty_per_g = 0.125

[sampling]
rate_hz = 100.0

[[axes]]
name = "x"
c1 = 0.03
c2 = -0.02
T = 200.0

[[axes]]
name = "y"
c1 = -0.02
c2 = 0.04
T = 150.0

[noise]
sigma_n = 1.0
sigma_eps = 1.0e-3
R = 5.5e-4

[ranges]
max_velocity_m_s = 60.0
max_position_m = 20000.0
max_run_s = 3600.0

[filter]
initial_sigma = [0.0, 0.0, 0.05, 0.05]
"""


@pytest.fixture(scope="module")
def default():
    return load_model()


@pytest.fixture(scope="module")
def duty():
    return loads_model(DUTY_TOML, source="<adxl202_like>")


def variant(**values) -> Model:
    """The default model with some keys replaced (every line ``key = ...`` of the file)."""
    text = DEFAULT_MODEL.read_text(encoding="utf-8")
    for key, value in values.items():
        text, n = re.subn(rf"^{key}\s*=.*$", f"{key} = {value}", text, flags=re.M)
        assert n >= 1, f"no key {key} in the default model"
    return loads_model(text, source=f"<default with {values}>")


def datasheet_noise(model: Model) -> tuple[float, float]:
    """(sigma [m/s^2], rho) of the sampled noise, written out here rather than taken from hil_sim.

    White noise of density d [g/sqrt(Hz)] through one pole at B [Hz] has the
    noise bandwidth (pi/2) B, so sigma^2 = (d G0)^2 (pi/2) B; sampled at Ts it
    is AR(1) with rho = exp(-2 pi B Ts).
    """
    d, B = model.sensor.noise_density_g_rthz, model.sensor.bandwidth_hz
    return d * G0 * math.sqrt(math.pi / 2 * B), math.exp(-2 * math.pi * B / model.rate_hz)


def batch_se(x: np.ndarray, batches: int = 50) -> float:
    """Standard error of mean(x) for serially correlated x, from batch means."""
    n = len(x) // batches * batches
    means = x[:n].reshape(batches, -1).mean(axis=1)
    return float(means.std(ddof=1) / math.sqrt(batches))


def fd_tolerance(f: np.ndarray, h: float) -> float:
    """Bound on |central difference of F - f| for F' = f on a grid of step h.

    The central difference of F at step h differs from f by at most
    h^2/6 max|f''|; max|f''| is estimated from second differences of f on
    the grid and doubled; 1e-8 (1 + max|f|) covers float64 rounding.
    """
    f2 = np.abs(np.diff(f, 2)).max() / h**2 if len(f) > 2 else 0.0
    return 2.0 * h**2 / 6.0 * f2 + 1e-8 * (1.0 + np.abs(f).max())


# --------------------------------------------------------------------------
# Reproducibility and random streams


@pytest.mark.parametrize("scenario", ["stop_and_go", "shock"])
def test_same_seed_same_run_different_seed_different_run(default, scenario):
    one = simulate(default, scenario, 60.0, 7).to_arrays()
    two = simulate(default, scenario, 60.0, 7).to_arrays()
    other = simulate(default, scenario, 60.0, 8).to_arrays()
    assert one.keys() == two.keys()
    for key in one:
        assert np.array_equal(one[key], two[key]), key
    for key in ("a", "eps", "accel", "code"):
        assert not np.array_equal(one[key], other[key]), key


def test_shorter_run_is_prefix_and_axis_subset_gives_same_columns(default):
    # stress: about 64 pulse pairs (one batch of random draws) every 15 s, so 45 s crosses batches
    full = simulate(default, "stress", 120.0, 3)
    short = simulate(default, "stress", 45.0, 3)
    only_y = simulate(default, "stress", 120.0, 3, axes=["y"])
    n = len(short.t)
    assert n == 4500
    for key in ("r", "u", "a", "eps", "code", "accel", "clipped"):
        assert np.array_equal(getattr(full, key)[:n], getattr(short, key)), key
        assert np.array_equal(getattr(full, key)[:, 1], getattr(only_y, key)[:, 0]), key
    assert only_y.axis_names == ("y",)


def test_axes_see_scaled_copies_of_one_motion(default):
    run = simulate(default, "stop_and_go", 60.0, 4)
    for key in ("r", "u", "a"):
        x = getattr(run, key)
        assert np.abs(x[:, 0]).max() > 0
        assert np.array_equal(x[:, 1], AXIS_GAIN[1] / AXIS_GAIN[0] * x[:, 0]), key
    assert not np.array_equal(run.eps[:, 0], run.eps[:, 1])


def test_initial_random_changes_only_the_bias_start(default):
    on = simulate(default, "stop_and_go", 60.0, 9, initial_random=True)
    off = simulate(default, "stop_and_go", 60.0, 9, initial_random=False)
    for key in ("r", "u", "a"):
        assert np.array_equal(getattr(on, key), getattr(off, key))
    for j, ax in enumerate(default.axes):
        assert off.eps[0, j] == ax.c2
        delta = on.eps[0, j] - off.eps[0, j]
        assert delta != 0.0
        decay = np.exp(-on.t / ax.T)  # the start deviation decays with the bias time constant
        np.testing.assert_allclose(on.eps[:, j] - off.eps[:, j], delta * decay, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------
# Truth trajectories


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_truth_is_consistent_r_u_a(default, scenario):
    """Central differences of r and u on a fine grid equal u and a within the bound of fd_tolerance.

    2 kHz over 240 s; 20 kHz over 60 s for stress and shock, whose pulse edges are 5-15 ms, and for
    walking, whose heel-strike and toe-off pulses last 20-40 ms.
    """
    h, duration = (5e-5, 60.0) if scenario in ("stress", "shock", "walking") else (5e-4, 240.0)
    t = np.arange(0.0, duration, h)
    r, u, a = truth(scenario, t, np.random.default_rng(11), default.max_accel_m_s2)
    assert r.dtype == u.dtype == a.dtype == np.float64 and r.shape == t.shape
    assert r[0] == 0.0 and u[0] == 0.0 and a[0] == 0.0
    du = (u[2:] - u[:-2]) / (2 * h)
    dr = (r[2:] - r[:-2]) / (2 * h)
    tol_a = fd_tolerance(a, h)
    tol_u = fd_tolerance(u, h)
    assert np.abs(du - a[1:-1]).max() <= tol_a
    assert np.abs(dr - u[1:-1]).max() <= tol_u
    if scenario != "stationary":  # the bounds are tight enough to mean something
        assert tol_a < 1e-2 * np.abs(a).max()
        assert tol_u < 1e-2 * np.abs(u).max()


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_truth_stays_within_declared_ranges_for_an_hour(default, scenario, seed):
    t = np.arange(int(default.ranges.max_run_s * default.rate_hz)) * default.Ts
    amax = default.max_accel_m_s2
    r, u, a = truth(scenario, t, np.random.default_rng(seed), amax)
    assert np.abs(u).max() <= default.ranges.max_velocity_m_s
    assert np.abs(r).max() <= default.ranges.max_position_m
    if scenario == "shock":
        assert np.abs(a).max() > 1.5 * amax
    else:
        assert np.abs(a).max() <= amax
    if scenario == "stress":
        assert a.max() >= 0.95 * amax and a.min() <= -0.95 * amax
    if scenario == "vehicle":
        assert 5.0 <= np.abs(u).max() <= 30.0 and np.abs(a).max() <= 3.0


@pytest.mark.parametrize("scenario,min_rest_s", [("stop_and_go", 2.0), ("vehicle", 5.0)])
def test_rests_are_exact(default, scenario, min_rest_s):
    """u == 0 exactly only in rests: long runs of samples, with a == 0 and r constant, on every axis."""
    run = simulate(default, scenario, 900.0, 5)
    at_rest = run.u[:, 0] == 0.0
    for j in range(run.n_axes):
        assert np.array_equal(run.u[:, j] == 0.0, at_rest)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], at_rest.astype(np.int8), [0]))))
    starts, stops = edges[::2], edges[1::2]
    assert len(starts) >= 10
    assert np.abs(run.u).max() > 1.0  # and it does move in between
    for k, (s0, s1) in enumerate(zip(starts, stops, strict=True)):
        if s1 < len(run.t):  # the last rest may be cut short by the end of the run
            assert (s1 - s0) >= min_rest_s * default.rate_hz - 1, f"rest {k} lasts {(s1 - s0) * default.Ts} s"
        assert np.all(run.a[s0:s1] == 0.0)
        assert np.all(run.r[s0:s1] == run.r[s0])


# --------------------------------------------------------------------------
# Clipping


def test_shock_clips_and_other_scenarios_do_not(default, duty):
    for model in (default, duty):
        run = simulate(model, "shock", 120.0, 1)
        assert run.clipped[:, 0].sum() >= 20
        if model.sensor.kind == "analog":
            full = 2**model.sensor.analog.adc_bits - 1
            assert np.all(np.isin(run.code[run.clipped], [0, full]))
        else:
            t1, t2 = run.t1[run.clipped], run.t2[run.clipped]
            assert np.all((t1 == 0) | (t1 == t2))
    for scenario in SCENARIOS:
        if scenario == "shock":
            continue
        for seed in (1, 2):
            assert not simulate(default, scenario, 600.0, seed).clipped.any(), (scenario, seed)
            assert not simulate(duty, scenario, 300.0, seed).clipped.any(), (scenario, seed)


# --------------------------------------------------------------------------
# Bias


def test_bias_mean_and_spread_follow_the_model(default):
    """Over 200 seeds the bias at fixed instants has the model's mean and variance.

    mean: c1 (1 - exp(-t/T)) + c2, within 4 SE (SE = sd / sqrt(seeds));
    variance: sigma0^2 phi^2k + Ts sigma_eps^2 (1 - phi^2k) / (1 - phi^2), the
    ratio of sample to model variance within 4 SE of 1 (SE = sqrt(2 / (seeds - 1))).
    """
    seeds = 200
    duration = 900.0
    k = np.array([0, 3000, 30000, 60000, 89999])
    eps = np.stack([simulate(default, "stationary", duration, s).eps[k] for s in range(seeds)])
    Ts, s0, se = default.Ts, default.filter.initial_sigma[3], default.noise.sigma_eps
    for j, ax in enumerate(default.axes):
        phi2k = np.exp(-2 * k * Ts / ax.T)
        var = s0**2 * phi2k + Ts * se**2 * (1 - phi2k) / (1 - np.exp(-2 * Ts / ax.T))
        mean = ax.c1 * (1 - np.exp(-k * Ts / ax.T)) + ax.c2
        z = (eps[:, :, j].mean(axis=0) - mean) / np.sqrt(var / seeds)
        assert np.abs(z).max() < N_SE, z
        ratio = eps[:, :, j].var(axis=0, ddof=1) / var
        assert np.abs(ratio - 1).max() < N_SE * math.sqrt(2 / (seeds - 1)), ratio


# --------------------------------------------------------------------------
# Noise and quantisation


def test_noise_is_ar1_with_the_datasheet_density():
    """accel - a - eps on a 16-bit ADC: std and lag-1 correlation of an AR(1) plus LSB^2/12.

    A 10 Hz output filter makes rho = exp(-2 pi 10 / 100) = 0.53 (large enough to
    measure); 16 bits make the noise sigma 4.4 LSB, so the rounding error is
    uniform and white. Expected: var = sigma^2 + LSB^2/12 within 4 SE, with
    SE(var) = var sqrt(2 (1 + rho^2) / (N (1 - rho^2))); lag-1 correlation
    rho sigma^2 / var within 4 SE, SE = sqrt((1 - rho^2) / N). Both axes of
    an hour, N = 720 000: the variance is resolved to +-0.9 % (4 SE).
    """
    model = variant(adc_bits=16, bandwidth_hz=10.0)
    run = simulate(model, "stationary", 3600.0, 21)
    e = (run.accel - run.a - run.eps).T.ravel()  # the axes' noises are independent: one long series
    sigma, rho = datasheet_noise(model)
    lsb = input_conversion(model, "x").scale
    var = sigma**2 + lsb**2 / 12
    n = len(e)
    se_var = var * math.sqrt(2 * (1 + rho**2) / (n * (1 - rho**2)))
    assert abs(e.var() - var) < N_SE * se_var
    ec = e - e.mean()
    r1 = np.dot(ec[1:], ec[:-1]) / np.dot(ec, ec)  # one spurious pair at the joint: negligible
    assert abs(r1 - rho * sigma**2 / var) < N_SE * math.sqrt((1 - rho**2) / n)
    assert abs(e.mean()) < N_SE * batch_se(e)


def _quantised_moments(model, axis, x):
    """Exact mean and variance of accel - x for a true x [m/s^2] plus Gaussian noise, through the ADC."""
    an = model.sensor.analog
    ax = model.axis(axis)
    sigma, _ = datasheet_noise(model)
    per_code = input_conversion(model, axis).scale  # m/s^2 per code
    mu = (ax.zero_g + ax.sensitivity * x / G0) / an.adc_ref_v * 2**an.adc_bits  # code, unrounded
    s = sigma / per_code
    j = np.floor(mu)[:, None] + np.arange(-8, 10)[None, :]  # +-8 codes covers > 20 sigma here
    p = norm.cdf((j + 0.5 - mu[:, None]) / s) - norm.cdf((j - 0.5 - mu[:, None]) / s)
    err = (j - mu[:, None]) * per_code
    m = (p * err).sum(axis=1)
    return m, (p * err**2).sum(axis=1) - m**2


@pytest.mark.parametrize("scenario", ["stationary", "stop_and_go"])
def test_default_adc_error_matches_exact_quantiser(default, scenario):
    """On the 12-bit default (noise sigma only 0.28 LSB) the ADC error is not LSB^2/12-white.

    Given the truth x = a + eps of each sample, the mean m(x) and variance
    v(x) of accel - x follow from the Gaussian noise and an ideal mid-tread
    ADC. Checked per axis (y has zero_g_v = 2.501 V, off the code grid):
    mean(e - m) within 4 SE and mean((e - m)^2 - v) within 4 SE (batch means).
    A floor instead of round, or a half-LSB offset, moves the first by 0.5 LSB.
    """
    run = simulate(default, scenario, 600.0, 31)
    sigma, _ = datasheet_noise(default)
    for j, name in enumerate(run.axis_names):
        x = run.a[:, j] + run.eps[:, j]
        m, v = _quantised_moments(default, name, x)
        d = run.accel[:, j] - x - m
        assert abs(d.mean()) < N_SE * batch_se(d), name
        q = d**2 - v
        assert abs(q.mean()) < N_SE * batch_se(q), name
        assert 0.5 * sigma**2 < v.mean() < 2 * (sigma**2 + input_conversion(default, name).scale ** 2)


@pytest.mark.parametrize("scenario", ["stop_and_go", "stress"])
def test_noiseless_adc_is_within_half_an_lsb(scenario):
    model = variant(noise_density_g_rthz=0.0, sigma_eps=0.0, c1=0.0, c2=0.0)
    run = simulate(model, scenario, 300.0, 2, initial_random=False)
    assert np.all(run.eps == 0.0)
    for j, name in enumerate(run.axis_names):
        half = input_conversion(model, name).scale / 2
        err = np.abs(run.accel[:, j] - run.a[:, j])
        assert err.max() <= half * (1 + 1e-9)
        assert err.max() > 0.9 * half  # it does quantise


# --------------------------------------------------------------------------
# Duty-cycle read-out


def test_duty_cycle_counts_convert_back_to_truth(duty):
    """ADXL202-like part: T2 = 5000 +-1 on 10 % of samples; T1/T2 gives a + eps + noise.

    The duty step is 1/5000, 1.57e-2 m/s^2, smaller than the noise sigma
    (1.74e-2 m/s^2), so the rounding error is uniform and independent:
    var(accel - a - eps) = sigma^2 + step^2/12 within 4 SE, the mean is 0
    within 4 SE and no sample is off by more than 6 sigma.
    """
    run = simulate(duty, "stop_and_go", 600.0, 17)
    nominal = duty.sensor.duty_cycle.t2_counts
    assert nominal == 5000
    sigma, rho = datasheet_noise(duty)
    assert not run.clipped.any()
    assert run.code is None
    for j, name in enumerate(run.axis_names):
        t2 = run.t2[:, j]
        assert set(np.unique(t2)) == {nominal - 1, nominal, nominal + 1}
        off = np.mean(t2 != nominal)
        assert abs(off - JITTER_FRACTION) < N_SE * math.sqrt(JITTER_FRACTION * (1 - JITTER_FRACTION) / len(t2))
        conv = input_conversion(duty, name)
        np.testing.assert_array_equal(run.accel[:, j], conv.accel(run.t1[:, j], t2))
        e = run.accel[:, j] - run.a[:, j] - run.eps[:, j]
        step = G0 / (nominal * duty.axis(name).sensitivity)
        var = sigma**2 + step**2 / 12
        n = len(e)
        se_var = var * math.sqrt(2 * (1 + rho**2) / (n * (1 - rho**2)))
        assert abs(e.var() - var) < N_SE * se_var, name
        assert abs(e.mean()) < N_SE * batch_se(e), name
        assert np.abs(e).max() < 6 * math.sqrt(var), name


# --------------------------------------------------------------------------
# Run files and refusals


@pytest.mark.parametrize("which", ["default", "duty"])
def test_round_trip_through_npz(tmp_path, default, duty, which):
    model = default if which == "default" else duty
    run = simulate(model, "shock", 20.0, 12)
    path = tmp_path / "run.npz"
    np.savez(path, **run.to_arrays())
    with np.load(path, allow_pickle=False) as npz:
        back = SimRun.from_arrays(model, {k: npz[k] for k in npz.files})
    assert (back.scenario, back.seed, back.axis_names) == (run.scenario, run.seed, run.axis_names)
    for key in ("t", "r", "u", "a", "eps", "code", "t1", "t2", "clipped", "accel"):
        mine, theirs = getattr(run, key), getattr(back, key)
        assert (mine is None) == (theirs is None), key
        if mine is not None:
            assert mine.dtype == theirs.dtype and np.array_equal(mine, theirs), key
    other = duty if which == "default" else default
    with pytest.raises(ValueError, match="missing"):
        SimRun.from_arrays(other, run.to_arrays())
    tampered = run.to_arrays()
    tampered["accel"] = tampered["accel"] + 0.01
    with pytest.raises(ValueError, match="^accel: "):
        SimRun.from_arrays(model, tampered)


@pytest.mark.parametrize(
    "args,kwargs,argument",
    [
        (("walk", 10.0, 1), {}, "scenario"),
        (("stationary", 0.0, 1), {}, "duration_s"),
        (("stationary", -5.0, 1), {}, "duration_s"),
        (("stationary", float("nan"), 1), {}, "duration_s"),
        (("stationary", 3600.5, 1), {}, "duration_s"),
        (("stationary", "10", 1), {}, "duration_s"),
        (("stationary", 10.0, -1), {}, "seed"),
        (("stationary", 10.0, 1.5), {}, "seed"),
        (("stationary", 10.0, 1), {"axes": ["z"]}, "axes"),
        (("stationary", 10.0, 1), {"axes": ["x", "x"]}, "axes"),
        (("stationary", 10.0, 1), {"axes": "x"}, "axes"),
    ],
)
def test_bad_arguments_are_refused_in_one_line(default, args, kwargs, argument):
    with pytest.raises(ValueError) as info:
        simulate(default, *args, **kwargs)
    msg = str(info.value)
    assert msg.startswith(f"{argument}: ") and "accepted" in msg and "\n" not in msg


def test_truth_refuses_unknown_scenario():
    with pytest.raises(ValueError, match=r"^name: unknown scenario 'walk'; accepted: 'stationary'"):
        truth("walk", np.arange(10) * 0.01, np.random.default_rng(0), 100.0)


def test_max_run_duration_is_accepted(default):
    run = simulate(default, "stationary", default.ranges.max_run_s, 0, axes=[0])
    assert len(run.t) == int(default.ranges.max_run_s * default.rate_hz)
    assert run.t[-1] < default.ranges.max_run_s


# --------------------------------------------------------------------------
# Walking (issue #11)


def test_walking_strides_stances_and_shocks(default):
    from accelnav.estimate.pipeline import stance_midpoints, stride_lengths
    from accelnav.estimate.zupt import intervals

    run = simulate(default, "walking", 120.0, 6)
    st = run.stance
    assert np.all(run.u[st] == 0.0) and np.all(run.a[st] == 0.0)
    assert np.all(np.linalg.norm(run.u[~st], axis=1) > 0)
    assert 0.30 <= st.mean() <= 0.40
    runs = intervals(st)
    durations = np.array([b - a for a, b in runs[:-1]]) * default.Ts
    assert durations.min() >= 0.28 and durations.max() <= 0.45
    starts = np.array([a for a, _ in runs]) * default.Ts
    assert 0.9 <= np.median(np.diff(starts)) <= 1.15  # about 1 Hz cadence
    lengths = stride_lengths(run.r, stance_midpoints(st))
    assert lengths.min() >= 1.2 - 1e-9 and lengths.max() <= 1.5 + 1e-9
    peak = np.abs(run.a).max() / 9.80665
    assert 12.0 <= peak <= 17.0  # heel strike / toe-off pulses to about 16 g
    # turns: the heading of the strides changes by more than 60 degrees over the run
    mids = stance_midpoints(st)
    d = np.diff(run.r[mids], axis=0)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    assert np.ptp(heading) > np.radians(60)
    # the tilt leak: at rest the sensor reads more than bias and noise explain
    leak = run.accel[st] - run.eps[st]
    assert np.abs(leak.mean(axis=0)).max() > 0.01


def test_sim_cli_walking_and_smooth_prints_strides(tmp_path, capsys):
    from accelnav.cli import main

    path = tmp_path / "w.npz"
    assert main(["sim", "--scenario", "walking", "--duration", "20", "--seed", "2", "--out", str(path)]) == 0
    assert main(["smooth", str(path), "--zupt", "auto", "--out", str(tmp_path / "s.npz")]) == 0
    out = capsys.readouterr().out
    # the figures themselves through the library: tests/estimate/test_stride_errors.py
    assert "stride length" in out and any(ln.startswith("smoother") for ln in out.splitlines())
