"""Overlapping Allan deviation, its Greenhall degrees of freedom and chi-square interval, in numpy.

These are the estimators allantools implements (``oadev`` on "frequency" data, ``edf_greenhall``
with d = 2, overlapping and unmodified, ``edf_simple``, ``confidence_interval``), written here for
the only case accelnav uses, so that a plain install does not pull allantools, whose declared
run-time dependencies include pytest and numpydoc with sphinx. allantools stays the oracle in the
tests (tests/identify/test_allan_oracle.py), which hold these to 1e-12 relative.

References: NIST SP 1065 eq. (11) and Table 5; C. A. Greenhall and W. J. Riley, "Uncertainty of
stability variances based on finite differences" (2004), eqs. (7)-(10) and Table 2.
"""

from __future__ import annotations

import math

import numpy as np

from accelnav.lazy import lazy_module

stats = lazy_module("scipy.stats")

_J_MAX = 100  # Greenhall: above this many lags the sum is replaced by its asymptote
# Greenhall Table 2, d = 2 (Allan variance): (a0, a1) per alpha for the unmodified variance
_TABLE2_D2 = {0: (2.0 / 3.0, 1.0 / 3.0), -1: (0.852, 0.375), -2: (1.079, 0.368)}


def phase(y: np.ndarray, rate_hz: float) -> np.ndarray:
    """Integral of the samples (less their mean, so a large offset costs no precision), starting at 0."""
    x = np.cumsum(y - np.mean(y)) * (1.0 / float(rate_hz))
    return np.concatenate(([0.0], x))


def oadev_phase(x: np.ndarray, rate_hz: float, m: int) -> tuple[float, int]:
    """Overlapping Allan deviation at tau = m / rate from phase ``x``, and the number of second differences."""
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    n = len(d)
    return float(np.sqrt(np.sum(d * d) / (2.0 * n)) / m * rate_hz), n


def _sw(t: np.ndarray, alpha: int) -> np.ndarray:
    # Greenhall eq. (7); alpha + 2 is used too, for the F = inf limit of eq. (8)
    if alpha == 2:
        return -np.abs(t)
    if alpha % 2 == 0:  # 0, -2: |t|^3, |t|^5
        return np.abs(t ** (3 - alpha))
    with np.errstate(divide="ignore", invalid="ignore"):  # 1, -1: t^2 ln|t|, t^4 ln|t|
        return np.where(t == 0, 0.0, t ** (3 - alpha) * np.log(np.abs(t)))


def _sx(t: np.ndarray, F: float, alpha: int) -> np.ndarray:
    # eq. (8); F = inf is the limit of a long filter
    if math.isinf(F):
        return _sw(t, alpha + 2)
    return F**2 * (2 * _sw(t, alpha) - _sw(t - 1.0 / F, alpha) - _sw(t + 1.0 / F, alpha))


def _sz(t: np.ndarray, F: float, alpha: int) -> np.ndarray:
    # eq. (9), d = 2
    return (
        6 * _sx(t, F, alpha)
        - 4 * _sx(t - 1.0, F, alpha)
        - 4 * _sx(t + 1.0, F, alpha)
        + _sx(t - 2.0, F, alpha)
        + _sx(t + 2.0, F, alpha)
    )


def _basic_sum(J: float, M: float, S: float, F: float, alpha: int) -> float:
    # eq. (10)
    j = np.arange(1, int(J), dtype=np.float64)
    first = _sz(np.array(0.0), F, alpha) ** 2
    second = (1 - J / M) * _sz(np.array(J / S), F, alpha) ** 2
    third = np.sum(2 * (1.0 - j / M) * _sz(j / S, F, alpha) ** 2)
    return float(first + second + third)


def edf_greenhall(alpha: int, m: int, n_phase: int) -> float:
    """Equivalent degrees of freedom of the overlapping Allan variance (d = 2, stride 1), rate noise alpha 0..-2."""
    if alpha not in _TABLE2_D2:
        raise ValueError(f"noise type alpha={alpha} is not a rate-noise type (0, -1, -2)")
    d = 2
    S = F = float(m)
    L = m / F + m * d
    M = 1 + math.floor(S * (n_phase - L) / m)
    J = min(M, (d + 1) * S)
    r = M / S
    if J <= _J_MAX:
        Fp = float(m) if m * (d + 1) <= _J_MAX else math.inf
        inv = _basic_sum(J, M, S, Fp, alpha) / (float(_sz(np.array(0.0), Fp, alpha)) ** 2 * M)
    elif r > d + 1:
        a0, a1 = _TABLE2_D2[alpha]
        inv = (1.0 / r) * (a0 - a1 / r)
    else:
        mp = _J_MAX / r
        inv = _basic_sum(_J_MAX, _J_MAX, mp, math.inf, alpha) / (
            float(_sz(np.array(0.0), math.inf, alpha)) ** 2 * _J_MAX
        )
    return 1.0 / inv


def edf_simple(n: int, m: int, alpha: int) -> float:
    """NIST SP 1065 Table 5 approximations (Stein 1985), rate noise alpha 0..-2; ``n`` phase points."""
    N, m = float(n), float(m)
    if alpha == 0:
        return ((3 * (N - 1) / (2 * m)) - (2 * (N - 2) / N)) * ((4 * m**2) / ((4 * m**2) + 5))
    if alpha == -1:
        return 2 * (N - 2) / (2.3 * N - 4.9) if m == 1 else 5 * N**2 / (4 * m * (N + (3 * m)))
    if alpha == -2:
        return (N - 2) / (m * (N - 3) ** 2) * ((N - 1) ** 2 - 3 * m * (N - 1) + 4 * m**2)
    raise ValueError(f"noise type alpha={alpha} is not a rate-noise type (0, -1, -2)")


def confidence_interval(dev: float, edf: float, ci: float) -> tuple[float, float]:
    """Two-sided chi-square interval of a deviation with ``edf`` degrees of freedom (NIST SP 1065 eq. 45)."""
    ci_l = min(abs(ci), abs(ci - 1)) / 2
    chi2_l = stats.chi2.ppf(ci_l, edf)
    chi2_h = stats.chi2.ppf(1 - ci_l, edf)
    var = dev * dev
    return float(np.sqrt(edf * var / chi2_h)), float(np.sqrt(edf * var / chi2_l))
