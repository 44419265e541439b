"""accelnav's own overlapping Allan deviation against allantools, the field's reference implementation.

allantools is a test dependency only (its declared run-time requirements pull pytest, numpydoc and
sphinx into a user's install); accelnav.identify.allan implements the same estimators. Same
estimator, same arithmetic: the deviation, the Greenhall degrees of freedom and the 95 % interval
agree to 1e-12 relative at every tau of the curve accelnav computes.
"""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from conftest import SHARED_DATA

from accelnav.identify import allan
from accelnav.identify.noiseid import CI, allan_deviation

allantools = pytest.importorskip("allantools")

RTOL = 1e-12
ADIS = SHARED_DATA / "adis16405_stationary" / "adis_16405_imu1.csv.gz"


def _allantools_curve(y: np.ndarray, rate: float, taus: np.ndarray, alpha: np.ndarray):
    """What noiseid computed with allantools before: oadev, edf_greenhall (else edf_simple), the interval."""
    t_out, dev, _, _ = allantools.oadev(y, rate=rate, data_type="freq", taus=taus)
    assert np.array_equal(np.round(t_out * rate), np.round(taus * rate))
    n_phase = len(y) + 1
    edf = []
    for a, m in zip(alpha, np.round(taus * rate).astype(int), strict=True):
        try:
            e = float(allantools.edf_greenhall(alpha=int(a), d=2, m=int(m), N=n_phase, overlapping=True))
        except (NotImplementedError, AssertionError, ZeroDivisionError, ValueError):
            e = float("nan")
        if not np.isfinite(e) or e <= 0:
            e = float(allantools.edf_simple(n_phase - 1, int(m), int(a)))
        edf.append(max(e, 1.0))
    edf = np.array(edf)
    ci = np.array([allantools.confidence_interval(d, e, ci=CI) for d, e in zip(dev, edf, strict=True)])
    return dev, edf, ci[:, 0], ci[:, 1]


def _check(y: np.ndarray, rate: float) -> None:
    c = allan_deviation(y, rate)
    dev, edf, lo, hi = _allantools_curve(y, rate, c.tau, c.alpha)
    np.testing.assert_allclose(c.adev, dev, rtol=RTOL, atol=0)
    np.testing.assert_allclose(c.edf, edf, rtol=RTOL, atol=0)
    np.testing.assert_allclose(c.lo, lo, rtol=RTOL, atol=0)
    np.testing.assert_allclose(c.hi, hi, rtol=RTOL, atol=0)


def test_white_noise_with_an_offset():
    y = 2.0 + 0.3 * np.random.default_rng(0).standard_normal(20_000)
    _check(y, 50.0)


def test_random_walk_on_white_noise():
    rng = np.random.default_rng(1)
    y = 0.01 * rng.standard_normal(100_000) + np.cumsum(3e-4 * rng.standard_normal(100_000))
    c = allan_deviation(y, 100.0)
    assert (c.alpha == -2).any() and (c.alpha == 0).any()  # both noise types' edf branches are compared
    _check(y, 100.0)


@pytest.mark.parametrize("m", [1, 7, 33, 34, 200, 5000])
@pytest.mark.parametrize("alpha", [0, -1, -2])
def test_greenhall_every_branch(alpha, m):
    # m <= 33 uses F = m in the basic sum, m >= 34 its F = inf limit; the long records reach Table 2
    for n_phase in (4 * m + 1, 40 * m + 1, 100_001):
        if 2 * m + 1 >= n_phase:
            continue
        ref = allantools.edf_greenhall(alpha=alpha, d=2, m=m, N=n_phase, overlapping=True)
        assert allan.edf_greenhall(alpha, m, n_phase) == pytest.approx(ref, rel=RTOL, abs=0)
    assert allan.edf_simple(10_000, m, alpha) == pytest.approx(allantools.edf_simple(10_000, m, alpha), rel=RTOL)


def test_shared_adis_recording():
    if not ADIS.is_file():
        pytest.skip(f"the real recording is not here: {ADIS} (../shared/data is absent on this machine)")
    with gzip.open(ADIS, "rt") as f:
        acc_z = np.loadtxt(f, delimiter=",", skiprows=1, usecols=6, max_rows=200_000)
    _check(acc_z * 9.80665, 100.0)
