"""The level frame's contract: a tilted still sensor levels to zero, a known attitude is applied as given,
the heading starts along x, and a record that cannot be levelled is refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
from support.quaternions import about, conj

from accelnav.errors import UserError
from accelnav.level import G, ImuRecord, level_frame, rotate

RATE = 100.0


def test_tilted_still_sensor_levels_to_no_acceleration():
    n = 1500
    t = np.arange(n) / RATE
    tilt = about(0, np.full(n, np.radians(25.0)))  # body -> level
    acc = rotate(conj(tilt), np.tile([0.0, 0.0, G], (n, 1)))  # gravity seen in the body
    out = level_frame(ImuRecord(t, acc, gyro=np.zeros((n, 3))))
    assert np.abs(out.acc[-200:]).max() < 0.02
    assert "tilt corrected at 1 rests" in out.method and out.rests.all()  # still throughout: one rest
    alone = level_frame(ImuRecord(t, acc, gyro=np.zeros((n, 3))), passes=0)  # no correction: Fusion's attitude
    assert "Fusion" in alone.method and np.abs(alone.acc[-200:]).max() < 0.02


def test_given_orientation_is_applied_and_heading_starts_along_x():
    n = 400
    t = np.arange(n) / RATE
    yaw = np.radians(40.0) + 0.5 * t  # turning at 0.5 rad/s, starting at 40 deg
    q = about(2, yaw)
    a_level = np.column_stack([np.sin(t), np.cos(t), np.zeros(n)])
    start = about(2, np.full(n, -np.radians(40.0)))
    body = rotate(conj(q), rotate(conj(start), a_level) + [0.0, 0.0, G])
    out = level_frame(ImuRecord(t, body, quat=q))
    np.testing.assert_allclose(out.acc, a_level, atol=1e-9)
    np.testing.assert_allclose(rotate(out.quat[:1], np.array([[1.0, 0, 0]])), [[1.0, 0, 0]], atol=1e-12)


@pytest.mark.parametrize(
    "kw, said",
    [
        ({}, "no gyroscope and no orientation"),
        ({"gyro": np.zeros((5, 3))}, "gyro has shape (5, 3), expected (10, 3)"),
        ({"quat": np.zeros((10, 4))}, "zero length"),
    ],
)
def test_refusals_are_one_line(kw, said):
    t = np.arange(10) / RATE
    with pytest.raises(UserError, match=None) as e:
        level_frame(ImuRecord(t, np.tile([0.0, 0.0, G], (10, 1)), **kw))
    assert said in str(e.value) and "\n" not in str(e.value)


def test_time_must_increase():
    with pytest.raises(UserError, match="strictly increasing"):
        ImuRecord(np.array([0.0, 0.1, 0.1]), np.zeros((3, 3)))
