"""A still signal read through a coarse step: what the step hides from the bias and noise figures.

A reading Q(x) = q round(x / q) of x = mu + n, n white with sd sigma:

* With sigma at least about half a step, the rounding error is uniform over one step (variance q^2 / 12)
  and independent of x: the n's characteristic function at 1/q, exp(-2 pi^2 sigma^2 / q^2), is then
  below 0.7 %. The reading's variance is sigma^2 + q^2 / 12 (Sheppard's correction) and its mean is mu to
  within (q / pi) sum_k exp(-2 pi^2 k^2 sigma^2 / q^2) / k (the Fourier series of the rounding error).
* With sigma well below a step, the reading sits on one or two codes. Its spread is the rounding's, not
  the sensor's, and its mean may be off mu by up to q / 2, however many samples are averaged: no fit can
  give the noise, and the bias is known to +-q/2 only.

The readings' spread cannot tell those cases apart (two codes half and half give the same variance for any
sigma well below a step), but the share of each code can: within a stretch short enough for mu to be
constant, P(code k) = Phi((k + 1/2 - mu) / sigma) - Phi((k - 1/2 - mu) / sigma). :func:`probit_sd` fits sigma
to the codes' counts in windows of the record (one mu per window, one sigma for all) by maximum likelihood,
with its 95 % profile interval. :func:`quantisation` calls the noise hidden below a quarter step
(``HIDDEN_BELOW``: there the rounding's error on the variance, (q/pi)^2 exp(-2 pi^2 sigma^2 / q^2), exceeds
half the noise variance, so no Allan or Sheppard figure is the sensor's), and gives the bound on the mean
at the interval's low end, which the bias intervals then carry.
:func:`grid_step` finds the step of samples that sit on a regular grid (a recording already converted
from codes). :func:`advice` says in one line how to make the noise visible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from accelnav.lazy import lazy_module

special = lazy_module("scipy.special")

CHI2_1_95 = 3.841458820694124  # 95 % quantile of chi-square with one degree of freedom
HIDDEN_BELOW = 0.25  # noise sd, in steps, below which the step hides the noise (see the module notes)
MAX_CODES = 64  # more codes than this in a record: the noise spans many steps, Sheppard's sd is used
MAX_WINDOWS = 256  # windows of the code-share fit (at least MIN_WINDOW samples each)
MIN_WINDOW = 200
SIGMA_GRID = np.geomspace(0.02, 3.0, 72)  # steps: the code-share fit's profile grid
GRID_TOL = 0.01  # spacings within this share of a step of whole steps: a grid (a file's decimals round them)
MAX_GRID_VALUES = 1 << 16  # more distinct values than this: not read as a grid (a 16-bit span at most)


@dataclass(frozen=True)
class Quantisation:
    """The step of one axis's readings and what it hides (SI units)."""

    step: float  # m/s^2
    source: str  # where the step came from: "the model's read-out" or "the samples' own grid"
    spread: float  # sd of the fit's residuals, m/s^2: the noise and the rounding together
    noise_sd: (
        float  # m/s^2: from the codes' shares (probit_sd), or Sheppard's sqrt(spread^2 - step^2/12) over MAX_CODES
    )
    noise_ci: tuple[float, float]  # its 95 % interval, m/s^2
    codes: int  # distinct values among the samples
    sensor_noise: float | None = None  # the datasheet's noise sd (the model's), m/s^2, if known
    finer: str | None = None  # a finer step the same part allows, said as a fix (e.g. "a 3.3 V reference: ...")

    @property
    def hidden(self) -> bool:
        """The step hides the noise: the corrected sd is below HIDDEN_BELOW steps."""
        return self.noise_sd < HIDDEN_BELOW * self.step

    @property
    def bias_bound(self) -> float:
        """How far the mean of the readings may sit from the mean of the signal, m/s^2: the rounding's Fourier
        bound at the low end of the noise's interval, at most q / 2."""
        q = self.step
        a = 2 * math.pi**2 * (self.noise_ci[0] / q) ** 2
        return min(q / 2, q / math.pi * sum(math.exp(-a * k * k) / k for k in range(1, 200)))


def grid_step(y: np.ndarray) -> float:
    """The step of a regular grid that every sample of ``y`` sits on (the spacings of its values all whole
    steps, to GRID_TOL of one: codes converted and written with a few decimals), or 0 when the samples are not
    on one (or hold too many values to be)."""
    values = np.unique(y[np.isfinite(y)])
    if len(values) < 2 or len(values) > MAX_GRID_VALUES:
        return 0.0
    gaps = np.diff(values)
    k = np.round(gaps / gaps.min())
    q = float(gaps.sum() / k.sum())  # least squares over every spacing: the smallest alone carries its rounding
    if q > 0 and np.all(np.abs(gaps - k * q) <= GRID_TOL * q):
        return q
    return 0.0


def probit_sd(y: np.ndarray, step: float) -> tuple[float, float, float]:
    """(sigma, low, high) [units of y]: the noise sd behind readings ``y`` on a grid of ``step``, by maximum
    likelihood from the share of each code in windows of the record (see the module notes), with its 95 %
    profile interval; an end at the grid's (SIGMA_GRID) means the data allow that far."""
    k = np.round((y - y.min()) / step).astype(np.int64) + 1  # an empty code each side: the tails not seen
    K = int(k.max()) + 2
    W = int(max(1, min(MAX_WINDOWS, len(k) // MIN_WINDOW)))
    w = np.arange(len(k)) * W // len(k)
    counts = np.bincount(w * K + k, minlength=W * K).reshape(W, K).astype(np.float64)
    codes = np.arange(K)
    held = counts > 0
    lo0 = np.where(held, codes, K).min(axis=1) - 1.0  # each window's mu lies within its codes, +-1
    hi0 = np.where(held, codes, -1).max(axis=1) + 1.0
    edges = np.arange(K + 1) - 0.5

    def loglik(mu: np.ndarray, sd: float) -> np.ndarray:
        cdf = special.ndtr((edges[None, :] - mu[:, None]) / sd)
        cdf[:, 0], cdf[:, -1] = 0.0, 1.0  # the end codes take the tails
        return (counts * np.log(np.maximum(np.diff(cdf, axis=1), 1e-300))).sum(axis=1)

    g = (math.sqrt(5) - 1) / 2
    prof = np.empty(len(SIGMA_GRID))
    for i, sd in enumerate(SIGMA_GRID):  # each window at its best mu: golden section (the likelihood is log-concave)
        a, b = lo0.copy(), hi0.copy()
        c, d = b - g * (b - a), a + g * (b - a)
        fc, fd = loglik(c, sd), loglik(d, sd)
        for _ in range(40):
            left = fc > fd
            b = np.where(left, d, b)
            a = np.where(left, a, c)
            c_new, d_new = b - g * (b - a), a + g * (b - a)
            f_new = loglik(np.where(left, c_new, d_new), sd)
            fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
            c, d = np.where(left, c_new, d), np.where(left, c, d_new)
        prof[i] = np.maximum(fc, fd).sum()
    best = int(np.argmax(prof))
    inside = np.nonzero(prof >= prof[best] - CHI2_1_95 / 2)[0]
    lo, hi = max(int(inside.min()) - 1, 0), min(int(inside.max()) + 1, len(SIGMA_GRID) - 1)  # the grid's spacing
    return float(SIGMA_GRID[best] * step), float(SIGMA_GRID[lo] * step), float(SIGMA_GRID[hi] * step)


def quantisation(y: np.ndarray, residuals: np.ndarray, step: float, source: str) -> Quantisation:
    """What a step of ``step`` [m/s^2] hides in samples ``y`` whose bias fit left ``residuals``."""
    spread = float(np.std(residuals))
    codes = int(np.ptp(np.round(y / step))) + 1
    if codes <= MAX_CODES:
        sd, lo, hi = probit_sd(y, step)
    else:
        sd = lo = hi = math.sqrt(max(0.0, spread**2 - step**2 / 12))
    return Quantisation(step, source, spread, sd, (lo, hi), codes)


def advice(q: Quantisation) -> str:
    """One line: the step hides the noise, and how to show it (with the model's noise, how fine a step would)."""
    mg = 1e3 / 9.80665
    lo, hi = q.noise_ci
    line = (
        f"the read-out step {q.step * mg:.3g} mg ({q.source}) hides the noise: the codes' shares put it at "
        f"{q.noise_sd / q.step:.2g} step (95 % {lo / q.step:.2g} .. {hi / q.step:.2g}), under {HIDDEN_BELOW:g} step, "
        f"where the rounding, not the sensor, makes the residual's spread, so no noise figure is fitted from it; "
        f"the bias is known to +-{q.bias_bound * mg:.3g} mg"
    )
    fixes = ["dither (noise of half a step or more ahead of the ADC) and average more samples per reading"]
    if q.finer:
        fixes.append(q.finer)
    noise = q.sensor_noise
    if noise is not None and 0 < 2 * noise < q.step:
        bits = math.ceil(math.log2(q.step / (2 * noise)))
        fixes.append(
            f"{bits} more ADC bit{'s' if bits > 1 else ''} (the model's sensor noise, {noise * mg:.2g} mg rms, "
            f"shows at a step of {2 * noise * mg:.2g} mg or less)"
        )
    return line + "; to measure it: " + ", or ".join(fixes)
