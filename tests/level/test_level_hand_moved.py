"""The rest detector on a slowly hand-moved unit (tests/support/hand_moved.py): smooth 4 s moves of up to
1 m/s^2 turning at <= 0.25 rad/s, inside a foot's stance tolerance (0.4 m/s^2, 0.5 rad/s) throughout, with
2 s still pauses between. Stillness is judged against the recording's own noise, the gyroscope's gravity
and the speed a rest would imply, so the pauses are found and the moves are not; the gyroscope's bias is
measured over the pauses; a record that is all motion or mostly rest says so."""

from __future__ import annotations

import numpy as np
import pytest
from support.hand_moved import hand_moved

from accelnav.level import ImuRecord, level_frame
from accelnav.level.rests import RestParams, spans

N = 20000  # 100 s at 200 Hz: 16 moves and pauses
NOISY = {"acc_noise": 0.02, "gyro_noise": 0.003, "bias_dps": (0.5, -0.3, 0.2)}  # a MEMS unit's figures
PAUSE_FOUND = 0.95  # share of every pause inside a rest
MOVE_AS_REST = 0.02  # share of the moves called rest at most (a rest's edge reaches into a move's still start)
BIAS_DPS = 0.02  # deg/s per axis: the bias measured within this of the truth (32 s of pauses, 0.17 deg/s noise)
HORIZONTAL_RMS = 0.1  # m/s^2: the level frame's horizontal acceleration during moves, rms error from the truth


def _pauses_found(sim, rests):
    return [rests[a:b].mean() for a, b in spans(~sim.moving)]


@pytest.mark.parametrize("kw", [{}, NOISY], ids=["noise-free", "noisy-biased"])
def test_the_pauses_are_rests_and_the_moves_are_not(kw):
    sim = hand_moved(N, **kw)
    out = level_frame(ImuRecord(sim.t, sim.acc, sim.gyro))
    found = _pauses_found(sim, out.rests)
    assert len(found) == 16 and min(found) >= PAUSE_FOUND, found
    assert out.rests[sim.moving].mean() <= MOVE_AS_REST, out.rests[sim.moving].mean()
    assert len(spans(out.rests)) == 16, out.notes  # one rest per pause, none inside a move
    notes = "\n".join(out.notes)
    assert "sensor noise" in notes and "measured over its quietest" in notes
    assert "refused: gravity turns in the body beyond what the gyroscope explains" in notes
    # the bias: measured over the pauses (still within the noise), named, and near the truth
    assert "measured over 16 rests still within the sensor's noise" in notes
    line = next(s for s in out.notes if s.startswith("gyro bias ("))
    measured = np.array([float(v) for v in line[len("gyro bias (") : line.index(")")].split(",")])
    np.testing.assert_allclose(measured, np.degrees(sim.bias), atol=BIAS_DPS)
    # the level frame during the moves
    err = out.acc[sim.moving, :2] - sim.level[sim.moving, :2]
    assert np.sqrt(np.mean(np.sum(err * err, axis=1))) <= HORIZONTAL_RMS


def test_a_foots_tolerance_alone_calls_the_moves_rest():
    """The test above can fail: the tolerance test alone (what the detector keeps as candidates) passes the
    moves, so only the other evidence refuses them."""
    from accelnav.level.rests import still_mask

    sim = hand_moved(N, **NOISY)
    assert still_mask(sim.acc, sim.gyro, 200.0)[sim.moving].mean() > 0.9


def test_a_stated_sensor_noise_is_used():
    sim = hand_moved(N, **NOISY)
    stated = RestParams(acc_noise=0.02, gyro_noise=0.003)
    out = level_frame(ImuRecord(sim.t, sim.acc, sim.gyro), detector=stated)
    assert "0.02 m/s^2, 0.003 rad/s rms per axis (as stated)" in out.notes[1]
    assert min(_pauses_found(sim, out.rests)) >= PAUSE_FOUND and out.rests[sim.moving].mean() <= MOVE_AS_REST


def test_a_record_that_is_all_motion_proves_no_noise_and_measures_no_bias():
    sim = hand_moved(N, pause_s=0.0, **NOISY)
    out = level_frame(ImuRecord(sim.t, sim.acc, sim.gyro))
    notes = "\n".join(out.notes)
    assert "the record proves no noise floor" in notes and "turn at up to" in notes
    assert "gyro bias not measured: no rest still within the sensor's noise" in notes
    assert out.rests.mean() <= 0.01, out.rests.mean()


def test_rests_covering_most_of_the_record_are_not_trusted_for_the_bias():
    sim = hand_moved(N, pause_s=10.0, **NOISY)  # 10 s pauses: 70 % of the record still
    out = level_frame(ImuRecord(sim.t, sim.acc, sim.gyro))
    notes = "\n".join(out.notes)
    assert out.rests.mean() > 0.6 and "rests cover 70% of the record (> 60%)" in notes
    assert "gyro bias not measured: rests cover 70%" in notes and "gyro bias (" not in notes
