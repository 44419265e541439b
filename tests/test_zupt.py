"""Automatic zero-velocity updates: the detector, and what they buy on stop-and-go runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from accelnav.estimate import zupt
from accelnav.estimate.pipeline import smooth_run
from accelnav.hil_sim.sensor import simulate

SEEDS = (101, 102, 103)


@pytest.mark.parametrize("seed", SEEDS)
def test_auto_zupt_smoothing_cuts_final_position_error_tenfold(default_model, seed):
    """Seeded stop-and-go, 120 s: smoother + automatic ZUPT vs the filter alone, at the end of the run."""
    arrays = simulate(default_model, "stop_and_go", 120.0, seed).to_arrays()
    plain = smooth_run(arrays, default_model)
    rest = zupt.rest_mask(arrays["accel"], arrays["clipped"], default_model)
    aided = smooth_run(arrays, default_model, rest=rest)
    for j in range(len(arrays["axis_names"])):
        truth = arrays["r"][-1, j]
        e_filter = abs(plain["filt_x"][j, -1, 0] - truth)
        e_smooth = abs(aided["smooth_x"][j, -1, 0] - truth)
        assert e_smooth * 10 <= e_filter, f"axis {j}: filter {e_filter:.3f} m, smoother+ZUPT {e_smooth:.3f} m"
        # and over the whole run, not only at its end
        rms = np.sqrt(np.mean((aided["smooth_x"][j, :, 0] - arrays["r"][:, j]) ** 2))
        assert rms < 1.0
    # the applied updates are at true rests (or within a few mm/s of one, at the edges of a move)
    speed = np.abs(arrays["u"][aided["zupt"][:, 0], 0])
    assert len(speed) > 100 and np.mean(speed < 0.02) > 0.97


def test_detector_finds_rests_and_not_holds_or_coasts(default_model):
    run = simulate(default_model, "stop_and_go", 120.0, 7)
    rest = zupt.rest_mask(run.accel, run.clipped, default_model)
    true_rest = np.all(run.u == 0, axis=1)
    # most of the true rest is found (the window trims each rest by half its length at both ends)
    assert np.mean(rest[true_rest]) > 0.8
    # what is flagged outside a rest has (near) zero acceleration: coasts, the ends of a move, not holds
    flagged_moving = rest & ~true_rest
    assert np.all(np.abs(run.a[flagged_moving, 0]) < 0.3)


def test_stationary_run_is_all_rest_but_the_edges(default_model):
    run = simulate(default_model, "stationary", 30.0, 4)
    rest = zupt.rest_mask(run.accel, run.clipped, default_model)
    w = zupt.window_samples(default_model, zupt.ZuptParams())
    assert not rest[: w // 2].any() and not rest[-(w // 2) :].any()
    assert rest[w // 2 : -(w // 2)].mean() > 0.97


def test_level_threshold_from_model(default_model):
    p = zupt.resolved(default_model, zupt.ZuptParams())
    w = zupt.window_samples(default_model, p)
    T = max(ax.T for ax in default_model.axes)
    spread = math.hypot(default_model.filter.initial_sigma[3], default_model.noise.sigma_eps * math.sqrt(T / 2))
    assert p.level == pytest.approx(3 * spread + 3 * math.sqrt(default_model.noise.R / w))
    assert zupt.resolved(default_model, zupt.ZuptParams(level=0.5)).level == 0.5


def test_update_samples_and_intervals(default_model):
    mask = np.zeros(100, dtype=bool)
    mask[10:35] = True
    mask[60:61] = True
    assert zupt.intervals(mask) == [(10, 35), (60, 61)]
    ks = zupt.update_samples(mask, default_model, zupt.ZuptParams(every_s=0.1))
    assert ks.tolist() == [10, 20, 30, 60]


@pytest.mark.parametrize("field,value", [("window_s", 0.0), ("var_k", -1.0), ("sigma", math.nan), ("gate", -1.0)])
def test_bad_parameters_refused(default_model, field, value):
    from dataclasses import replace

    with pytest.raises(ValueError, match=field.split("_s")[0]):
        zupt.resolved(default_model, replace(zupt.ZuptParams(), **{field: value}))


def test_clipped_samples_are_never_rest(default_model):
    run = simulate(default_model, "stationary", 10.0, 2)
    clipped = np.array(run.clipped)
    clipped[400:410, 1] = True
    rest = zupt.rest_mask(run.accel, clipped, default_model)
    w = zupt.window_samples(default_model, zupt.ZuptParams())
    assert not rest[400 - w // 2 : 410 + w // 2].any() and rest[200:300].all()
