"""The tuner's simulated case: one axis of the default model, samples of the filter's own process and position
fixes of its r. Shared by tests/estimate/test_tune.py and bench/coverage/coverage_tune.py."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from accelnav.estimate.kf import position_fix
from accelnav.model.design import axis_design
from accelnav.model.edit import revalidate, with_noise
from accelnav.model.load import DEFAULT_MODEL, load_model

TRUE = {"sigma_n": 1.0, "sigma_eps": 0.01, "R": 0.016}


def one_axis_model(**noise):
    m = load_model(DEFAULT_MODEL)
    m = dataclasses.replace(m, axes=(dataclasses.replace(m.axes[0], c1=0.0),))
    return revalidate(with_noise(m, **noise))


def process(model, n: int, seed: int, fix_every_s: float = 1.0, fix_sigma: float = 0.02):
    """Samples of the filter's own model and position fixes of its r: (accel (n, 1), valid, extras)."""
    rng = np.random.default_rng(seed)
    d = axis_design(model, 0)
    F, b = np.asarray(d.F), np.asarray(d.b)
    W = rng.standard_normal((n, 4)) @ np.linalg.cholesky(np.asarray(d.Q)).T
    x = np.asarray(d.x0) + np.sqrt(np.diag(np.asarray(d.P0))) * rng.standard_normal(4)
    X = np.empty((n, 4))
    for k in range(n):
        if k:
            x = F @ x + b + W[k]
        X[k] = x
    z = X[:, 2] + X[:, 3] + rng.standard_normal(n) * math.sqrt(d.R)
    step = int(round(fix_every_s * model.rate_hz))
    fixes = [position_fix(k, X[k, 0] + fix_sigma * rng.standard_normal(), fix_sigma) for k in range(step, n, step)]
    return z[:, None], np.ones((n, 1), dtype=bool), [fixes]
