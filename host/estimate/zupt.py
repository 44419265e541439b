"""Automatic zero-velocity updates: find the rests in the raw acceleration, turn them into measurements.

The detector (one decision per sample, for the whole body: a rest is a rest
of every axis at once)
----------------------------------------------------------------------------
Over a centred window of W = round(window_s * rate) samples (odd, at least 3),
per axis j, on the measured acceleration z_j minus the model's bias mean
eps_j(k) = (c1 + c2) - c1 phi^k:

1. **quiet**: the window's sample variance is at most ``var_k * R``. Pure
   sensor noise has variance R (the model's measurement noise); any change of
   acceleration inside the window adds to it. Default var_k = 2 (for W = 51
   the 0.1 % quantile of R chi2(W-1)/(W-1) is 1.6 R).
2. **level**: the window's mean is within ``level`` of the bias mean, i.e. the
   acceleration is near zero. Default level = 3 sqrt(sigma_eps0^2 +
   sigma_eps^2 T/2) + 3 sqrt(R/W): three standard deviations of the bias about
   its model (initial uncertainty initial_sigma[3] plus the stationary spread
   of the Gauss-Markov walk) plus three of the window mean. This rejects the
   constant-acceleration holds of a move, which pass the quiet test.
3. every sample of the window valid (not clipped) on every axis.

A sample is *at rest* when 1-3 hold on every axis. Quiet and level cannot
tell a rest from coasting at constant velocity (a = 0 either way), so each
zero-velocity update is also **gated** in the filter: it is applied only if
its innovation passes y^2 <= gate S, S = P_uu + sigma^2 (a chi-square test
with one degree of freedom; default gate = 16, four sigma). During a coast the
filter's velocity is far from zero with a small variance, and the update is
refused; after a move that returns to rest it is accepted.

Measurements: within each run of rest samples, one zero-velocity update
(:func:`accelnav.estimate.kf.zero_velocity`, u = 0 with standard deviation ``sigma``) every
``every_s`` seconds, from the run's first sample. Updating at every sample of
a long rest would treat 100 readings of the same zero velocity per second as
independent evidence and cost general-path time for nothing; one per 0.1 s
keeps the velocity pinned (its drift in 0.1 s at rest is far below sigma).

All thresholds have command-line overrides (``accelnav smooth --zupt-*``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from accelnav.codegen.design import axis_design
from accelnav.codegen.model import Model
from accelnav.estimate.kf import Measurement, bias_model, zero_velocity


@dataclass(frozen=True)
class ZuptParams:
    window_s: float = 0.5  # s, centred window of the moving mean and variance
    var_k: float = 2.0  # quiet if the window variance <= var_k * R
    level: float | None = None  # m/s^2, |window mean - bias mean| bound; None: from the model
    sigma: float = 0.01  # m/s, standard deviation of each zero-velocity update
    every_s: float = 0.1  # s, one update per every_s within a rest
    gate: float = 16.0  # chi-square gate on the update's innovation; 0 applies every update


def window_samples(model: Model, p: ZuptParams) -> int:
    w = max(3, int(round(p.window_s * model.rate_hz)))
    return w if w % 2 else w + 1


def resolved(model: Model, p: ZuptParams) -> ZuptParams:
    """``p`` with the level threshold filled in from the model (see the module docstring)."""
    for name in ("window_s", "var_k", "sigma", "every_s"):
        v = getattr(p, name)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"zupt {name}: got {v}; accepted: a number > 0")
    if not (math.isfinite(p.gate) and p.gate >= 0):
        raise ValueError(f"zupt gate: got {p.gate}; accepted: a number >= 0 (0: no gate)")
    if p.level is not None:
        if not (math.isfinite(p.level) and p.level > 0):
            raise ValueError(f"zupt level: got {p.level}; accepted: a number > 0 (m/s^2)")
        return p
    w = window_samples(model, p)
    T = max(ax.T for ax in model.axes)
    s0 = model.filter.initial_sigma[3]
    spread = math.sqrt(s0**2 + model.noise.sigma_eps**2 * T / 2.0)
    return replace(p, level=3.0 * spread + 3.0 * math.sqrt(model.noise.R / w))


def _moving(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving sum over w (odd) samples; NaN where the window leaves the run."""
    n = len(x)
    out = np.full(n, np.nan)
    if n < w:
        return out
    c = np.concatenate(([0.0], np.cumsum(x)))
    h = w // 2
    out[h : n - h] = c[w:] - c[: n - w + 1]
    return out


def rest_mask(accel: np.ndarray, clipped: np.ndarray, model: Model, params: ZuptParams = ZuptParams()) -> np.ndarray:
    """(N,) bool: samples at rest on every axis. ``accel``, ``clipped`` are (N, n_axes) as in a run file.

    Columns are taken to be the model's axes in order (a run's axis_names).
    """
    p = resolved(model, params)
    accel = np.asarray(accel, dtype=np.float64)
    clipped = np.asarray(clipped, dtype=bool)
    n, n_axes = accel.shape
    w = window_samples(model, p)
    rest = np.ones(n, dtype=bool)
    for j in range(n_axes):
        d = axis_design(model, j)
        ok = ~clipped[:, j] & np.isfinite(accel[:, j])
        x = np.where(ok, accel[:, j] - bias_model(d, n), 0.0)
        bad = _moving((~ok).astype(np.float64), w)
        s1 = _moving(x, w)
        s2 = _moving(x * x, w)
        with np.errstate(invalid="ignore"):
            mean = s1 / w
            var = (s2 - w * mean * mean) / (w - 1)
            rest &= (bad == 0) & (var <= p.var_k * d.R) & (np.abs(mean) <= p.level)
    return rest


def intervals(mask: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in ``mask`` as (first, last + 1) sample pairs."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def update_samples(mask: np.ndarray, model: Model, params: ZuptParams = ZuptParams()) -> np.ndarray:
    """Sample indices that get a zero-velocity update: every every_s seconds within each rest run."""
    step = max(1, int(round(params.every_s * model.rate_hz)))
    ks = [np.arange(a, b, step) for a, b in intervals(mask)]
    return np.concatenate(ks) if ks else np.zeros(0, dtype=np.int64)


def measurements(ks: np.ndarray, params: ZuptParams = ZuptParams()) -> tuple[list[Measurement], list[float]]:
    """Zero-velocity updates at samples ``ks`` and their gates (for accelnav.estimate.fastsmooth.smooth)."""
    extras = [zero_velocity(int(k), params.sigma) for k in ks]
    return extras, [params.gate] * len(extras)


def intervals_from_csv(path, t: np.ndarray) -> np.ndarray:
    """A rest mask from a CSV of intervals (columns start_s, end_s; inclusive), on the sample times t."""
    from accelnav.estimate.fixes import read_table

    rows = read_table(path, required=("start_s", "end_s"), optional=())
    mask = np.zeros(len(t), dtype=bool)
    for i, (a, b) in enumerate(zip(rows["start_s"], rows["end_s"], strict=True)):
        if not b >= a:
            from accelnav.errors import UserError

            raise UserError(f"{path}: row {i + 2}: end_s {b:g} is before start_s {a:g}")
        mask |= (t >= a) & (t <= b)
    return mask
