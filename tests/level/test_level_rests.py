"""The gyroscope-aided rest detector and the rests' tilt correction on records whose truth is known."""

from __future__ import annotations

import numpy as np
import pytest
from support.quaternions import about, conj

from accelnav.errors import UserError
from accelnav.level import G, ImuRecord, level_frame, rotate
from accelnav.level.rests import RestParams, shoe_statistic, spans, still_mask

RATE = 100.0


def _rocking(n_cycles=6, still_s=1.0, move_s=1.0, bias_dps=(0.0, 0.0, 0.0), seed=1):
    """A sensor still for ``still_s``, then turned once round x for ``move_s`` (the rate a half sine, zero
    only at the ends), repeated; its gyro reads the rate plus ``bias_dps`` and noise, its accelerometer gravity
    (the rocking's own acceleration left out: a pure rotation about the sensor)."""
    rng = np.random.default_rng(seed)
    ns, nm = int(still_s * RATE), int(move_s * RATE)
    angle = np.concatenate(
        [np.zeros(ns)] + [np.r_[np.pi * (1 - np.cos(np.pi * np.arange(nm) / nm)), np.zeros(ns)]] * n_cycles
    )
    n = angle.size
    t = np.arange(n) / RATE
    rate = np.gradient(angle, t)
    q = about(0, angle)
    acc = rotate(conj(q), np.tile([0.0, 0.0, G], (n, 1))) + 0.02 * rng.standard_normal((n, 3))
    gyro = (
        np.column_stack([rate, np.zeros(n), np.zeros(n)]) + np.radians(bias_dps) + 0.002 * rng.standard_normal((n, 3))
    )
    still = np.abs(rate) < 1e-9
    return t, acc, gyro, still


def test_the_detector_finds_the_still_spells_and_not_the_rocking():
    t, acc, gyro, still = _rocking()
    mask = still_mask(acc, gyro, RATE)
    assert len(spans(mask)) == 7
    assert mask[still].mean() > 0.9 and mask[~still].mean() < 0.1
    # the gyroscope term decides: with an accelerometer tolerance too loose to see the turn ...
    loose = RestParams(acc_tol=100.0)
    assert still_mask(acc, gyro, RATE, loose)[~still].mean() < 0.1
    # ... a gyroscope tolerance above the turn's rate (up to pi^2 rad/s) calls it rest
    assert still_mask(acc, gyro, RATE, RestParams(acc_tol=100.0, gyro_tol=20.0))[~still].mean() > 0.9


def test_the_statistic_is_in_physical_units():
    n = 50
    acc = np.tile([0.0, 0.0, G + 0.5], (n, 1))  # 0.5 m/s^2 off gravity's magnitude, no rotation
    gyro = np.tile([0.0, 0.3, 0.0], (n, 1))  # 0.3 rad/s
    s = shoe_statistic(acc, gyro, RATE, RestParams(acc_tol=1.0, gyro_tol=0.6))
    np.testing.assert_allclose(s, 0.5**2 / 1.0 + 0.3**2 / 0.6**2, rtol=1e-9)


def test_rests_correct_a_gyro_bias_and_the_leak_is_stated():
    # still spells of 1.2 s: the bias is measured over rests still within the noise for 1 s or more
    t, acc, gyro, still = _rocking(still_s=1.2, bias_dps=(1.0, -0.8, 0.3))
    out = level_frame(ImuRecord(t, acc, gyro=gyro))
    assert np.abs(out.acc[still, :2]).max() < 0.1, np.abs(out.acc[still, :2]).max()
    assert out.leak < 0.05 and "residual level leak" in out.summary()
    # the leak at the rests is small by construction: the summary also says what is left between them
    assert np.isfinite(out.between) and f"about {out.between:.3g} m/s^2 between them" in out.summary()
    notes = " ".join(out.notes)
    assert "7 rests found" in notes and "gyro bias (1, -0.8" in notes
    # without the rests' correction the uncorrected bias tilts the frame between them
    plain = level_frame(ImuRecord(t, acc, gyro=gyro), passes=0)
    assert np.abs(plain.acc[still, :2]).max() > 3 * np.abs(out.acc[still, :2]).max()


def test_given_rests_as_times_and_as_a_mask_agree():
    t, acc, gyro, still = _rocking(bias_dps=(0.5, 0.0, 0.0))
    times = np.array([(t[a], t[b - 1]) for a, b in spans(still)])
    by_times = level_frame(ImuRecord(t, acc, gyro=gyro), rests=times)
    by_mask = level_frame(ImuRecord(t, acc, gyro=gyro), rests=still)
    np.testing.assert_array_equal(by_times.rests, still)
    np.testing.assert_allclose(by_times.acc, by_mask.acc, atol=1e-12)
    assert "7 rests given" in by_times.notes[0]


def test_a_record_that_never_rests_says_so():
    n = 1000
    t = np.arange(n) / RATE
    spin = np.column_stack([np.full(n, 2.0), np.zeros(n), np.zeros(n)])  # turning at 2 rad/s throughout
    angle = 2.0 * t
    acc = rotate(conj(about(0, angle)), np.tile([0.0, 0.0, G], (n, 1)))
    out = level_frame(ImuRecord(t, acc, gyro=spin))
    assert not np.isfinite(out.leak) and "no rest to measure it" in out.summary()
    assert "Fusion" in out.method and any("no rest" in s for s in out.notes)


@pytest.mark.parametrize(
    "rests, said",
    [
        (np.zeros(5, dtype=bool), "mask of shape (5,)"),
        (np.array([[2.0, 1.0]]), "start <= end"),
        (np.array([1.0, 2.0, 3.0]), "(start, end) times"),
    ],
)
def test_bad_rests_are_refused_in_one_line(rests, said):
    t = np.arange(10) / RATE
    with pytest.raises(UserError) as e:
        level_frame(ImuRecord(t, np.tile([0.0, 0.0, G], (10, 1)), gyro=np.zeros((10, 3))), rests=rests)
    assert said in str(e.value) and "\n" not in str(e.value)
