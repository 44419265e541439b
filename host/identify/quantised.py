"""A still signal read through a coarse step: what the step hides from the bias and noise figures.

A reading Q(x) = q round(x / q) of x = mu + n, n white with sd sigma:

* With sigma at least about half a step, the rounding error is uniform over one step (variance q^2 / 12)
  and independent of x: the n's characteristic function at 1/q, exp(-2 pi^2 sigma^2 / q^2), is then
  below 0.7 %. The reading's variance is sigma^2 + q^2 / 12 (Sheppard's correction) and its mean is mu to
  within (q / pi) sum_k exp(-2 pi^2 k^2 sigma^2 / q^2) / k (the Fourier series of the rounding error).
* With sigma well below a step, the reading sits on one or two codes. Its spread is the rounding's, not
  the sensor's, and its mean may be off mu by up to q / 2, however many samples are averaged: no fit can
  give the noise, and the bias is known to +-q/2 only.

:func:`quantisation` decides which case a fit's residuals are in, by the Sheppard-corrected sd against
half a step (the one threshold, ``HIDDEN_BELOW``), and gives the half-width that the bias intervals must
grow by where the noise is hidden (elsewhere the bound is under 0.3 % of a step, and left out).
:func:`grid_step` finds the step of samples that sit on a regular grid (a recording already converted
from codes). :func:`advice` says in one line how to make the noise visible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

HIDDEN_BELOW = 0.5  # noise sd, in steps, below which the step hides the noise (see the module notes)
GRID_TOL = 0.01  # spacings within this share of a step of whole steps: a grid (a file's decimals round them)
MAX_GRID_VALUES = 1 << 16  # more distinct values than this: not read as a grid (a 16-bit span at most)


@dataclass(frozen=True)
class Quantisation:
    """The step of one axis's readings and what it hides (SI units)."""

    step: float  # m/s^2
    source: str  # where the step came from: "the model's read-out" or "the samples' own grid"
    spread: float  # sd of the fit's residuals, m/s^2: the noise and the rounding together
    noise_sd: float  # Sheppard-corrected: sqrt(max(0, spread^2 - step^2 / 12))
    codes: int  # distinct values among the samples
    sensor_noise: float | None = None  # the datasheet's noise sd (the model's), m/s^2, if known
    finer: str | None = None  # a finer step the same part allows, said as a fix (e.g. "a 3.3 V reference: ...")

    @property
    def hidden(self) -> bool:
        """The step hides the noise: the corrected sd is below HIDDEN_BELOW steps."""
        return self.noise_sd < HIDDEN_BELOW * self.step

    @property
    def bias_bound(self) -> float:
        """How far the mean of the readings may sit from the mean of the signal, m/s^2: q / 2 when the noise
        is hidden; else the rounding's Fourier bound at the corrected sd (under 0.3 % of a step)."""
        q = self.step
        if self.hidden:
            return q / 2
        a = 2 * math.pi**2 * (self.noise_sd / q) ** 2
        return min(q / 2, q / math.pi * sum(math.exp(-a * k * k) / k for k in range(1, 50)))


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


def quantisation(y: np.ndarray, residuals: np.ndarray, step: float, source: str) -> Quantisation:
    """What a step of ``step`` [m/s^2] hides in samples ``y`` whose bias fit left ``residuals``."""
    spread = float(np.std(residuals))
    noise_sd = math.sqrt(max(0.0, spread**2 - step**2 / 12))
    return Quantisation(step, source, spread, noise_sd, int(len(np.unique(y))))


def advice(q: Quantisation) -> str:
    """One line: the step hides the noise, and how to show it (with the datasheet's noise, how fine a step
    would show it)."""
    mg = 1e3 / 9.80665
    line = (
        f"the read-out step {q.step * mg:.3g} mg ({q.source}) hides the noise: the residual sd "
        f"{q.spread / q.step:.2g} step is what rounding gives with a noise under {HIDDEN_BELOW:g} step, so no "
        f"noise figure is fitted from it and the bias is known to +-{q.bias_bound * mg:.3g} mg"
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
