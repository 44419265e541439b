"""Rests seen by the accelerometer and the gyroscope together: a SHOE-style detector.

Skog et al. (2010, "Zero-velocity detection: an algorithm evaluation") compare detectors for foot-mounted
IMUs; the best, SHOE, is the generalised likelihood ratio of "the body is still" over a window of W
samples, which reduces to two sums: how far each specific force is from one constant gravity vector of
magnitude g, and how large the angular rate is. Here the two are read in physical units:

    T = mean_W |a_k - g a_bar/|a_bar||^2 / acc_tol^2  +  mean_W |w_k - b|^2 / gyro_tol^2  <=  1

``acc_tol`` (m/s^2) is the rms departure of the specific force from a still gravity vector a rest may
show, ``gyro_tol`` (rad/s) the rms angular rate it may show (b: the gyroscope's bias, when known), the
two added in quadrature (SHOE's threshold gamma is 1 on this scale). The defaults (0.4 m/s^2, 0.5 rad/s)
were measured on real recordings: on gaitmap's foot walk a mid-stance turns at 0.3-0.65 rad/s (the window's
rms) as the foot rolls over and its specific force stays within 0.25-0.45 m/s^2 of gravity, the swing turns
at 3-10 rad/s; every reference stance of both feet holds a rest, 97 % of the motion-capture mid-stances
are inside one. On mobgap's lower-back walks (quiet standing 0.02-0.05 rad/s, walking 0.2-0.9 rad/s with
1-3 m/s^2) 0-5 % of the walking is called rest; with the looser (1.0 m/s^2, 0.6 rad/s) 14-19 % was. The
accelerometer term alone cannot tell a smooth cruise from a
stop (accelnav.estimate.zupt's candidates, the path for parts without a gyroscope); the gyroscope term
sees the turning a moving foot or body cannot avoid.

The window is centred; a centre that passes makes every sample of its window a rest sample (every sample
in it was seen still), and runs shorter than ``min_rest_s`` are dropped. All of it is vectorised:
moving sums by cumulative sums, no loop over samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from accelnav.errors import UserError

G = 9.80665  # m/s^2, the standard gravity (the level frame subtracts it)


@dataclass(frozen=True)
class RestParams:
    window_s: float = 0.05  # s, centred window of the test (SHOE's W: 3-11 samples at 100-200 Hz)
    acc_tol: float = 0.4  # m/s^2, rms departure of the specific force from one still gravity vector
    gyro_tol: float = 0.5  # rad/s (29 deg/s), rms angular rate a rest may show (a foot rolling in stance)
    min_rest_s: float = 0.05  # s, shorter runs of still samples are dropped

    def checked(self) -> RestParams:
        for name in ("window_s", "acc_tol", "gyro_tol"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise UserError(f"rest detector {name}: got {v}; accepted: a number > 0")
        if not (math.isfinite(self.min_rest_s) and self.min_rest_s >= 0):
            raise UserError(f"rest detector min_rest_s: got {self.min_rest_s}; accepted: a number >= 0")
        return self


def _window(rate: float, window_s: float) -> int:
    w = max(3, int(round(window_s * rate)))
    return w if w % 2 else w + 1


def _centred_mean(x: np.ndarray, w: int) -> np.ndarray:
    """Mean over the centred window of ``w`` (odd) samples of each row of ``x`` (N, ...), edges padded."""
    h = w // 2
    pad = np.concatenate([np.repeat(x[:1], h, axis=0), x, np.repeat(x[-1:], h, axis=0)])
    c = np.cumsum(pad, axis=0)
    c = np.concatenate([np.zeros_like(c[:1]), c])
    return (c[w:] - c[:-w]) / w


def shoe_statistic(
    acc: np.ndarray, gyro: np.ndarray, rate: float, params: RestParams = RestParams(), bias: np.ndarray | None = None
) -> np.ndarray:
    """(N,) the test statistic T of the module docstring at each window centre (rest where T <= 1)."""
    p = params.checked()
    w = _window(rate, p.window_s)
    wb = gyro if bias is None else gyro - bias
    mean_a = _centred_mean(acc, w)
    mean_a2 = _centred_mean(np.einsum("ij,ij->i", acc, acc), w)
    mean_w2 = _centred_mean(np.einsum("ij,ij->i", wb, wb), w)
    # mean |a - g u|^2 with u = a_bar/|a_bar|: mean |a|^2 - 2 g |a_bar| + g^2
    dev = np.maximum(mean_a2 - 2.0 * G * np.linalg.norm(mean_a, axis=1) + G * G, 0.0)
    return dev / p.acc_tol**2 + mean_w2 / p.gyro_tol**2


def still_mask(
    acc: np.ndarray, gyro: np.ndarray, rate: float, params: RestParams = RestParams(), bias: np.ndarray | None = None
) -> np.ndarray:
    """(N,) bool: the samples of the rests (every sample of a window whose centre passes; short runs dropped)."""
    p = params.checked()
    w = _window(rate, p.window_s)
    centre = shoe_statistic(acc, gyro, rate, p, bias) <= 1.0
    # every sample within w // 2 of a passing centre: a dilation by a moving sum
    mask = _centred_mean(centre.astype(np.float64), w) > 0.5 / w
    return drop_short(mask, int(math.ceil(p.min_rest_s * rate)))


def spans(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs of True in ``mask`` as half-open (start, stop) sample spans."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def drop_short(mask: np.ndarray, n: int) -> np.ndarray:
    """``mask`` without its runs shorter than ``n`` samples."""
    out = np.zeros(len(mask), dtype=bool)
    for a, b in spans(mask):
        if b - a >= n:
            out[a:b] = True
    return out
