"""A simulated hand-moved unit (the record bench/speed/bench_level.py times at scale): 4 s smooth moves along a
level path with up to 1 m/s^2 (a sine period of acceleration: still at both ends), each in another direction,
the attitude swaying in roll and pitch by up to 20 degrees and turning about the vertical (<= 0.25 rad/s)
while it moves, fully still in the 2 s pauses. Body frame, gravity in; the gyroscope the attitude's exact
rate, plus a bias and white noise when asked, the accelerometer white noise when asked."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

G = 9.80665


@dataclass
class HandMoved:
    t: np.ndarray  # (N,) s
    acc: np.ndarray  # (N, 3) m/s^2, body frame, gravity in
    gyro: np.ndarray  # (N, 3) rad/s, body frame, bias and noise in
    level: np.ndarray  # (N, 3) m/s^2, the true level-frame acceleration, gravity out (heading of the start)
    moving: np.ndarray  # (N,) bool, the moves
    bias: np.ndarray  # (3,) rad/s, the gyroscope's true bias


def hand_moved(
    n: int,
    rate: float = 200.0,
    acc_noise: float = 0.0,
    gyro_noise: float = 0.0,
    bias_dps=(0.0, 0.0, 0.0),
    move_s: float = 4.0,
    pause_s: float = 2.0,
    seed: int = 1,
) -> HandMoved:
    """``n`` samples at ``rate``; white noise of ``acc_noise`` m/s^2 and ``gyro_noise`` rad/s rms per axis, a
    gyroscope bias of ``bias_dps``; moves of ``move_s`` and pauses of ``pause_s`` (0: never still)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    phase = t % (move_s + pause_s)
    moving = phase < move_s
    a = np.where(moving, np.sin(2 * np.pi * phase / move_s), 0.0)
    heading = 0.7 * np.floor(t / (move_s + pause_s))
    level = np.stack([a * np.cos(heading), a * np.sin(heading), 0.3 * a], axis=1)
    tau = np.cumsum(moving) / rate  # the attitude moves only while the unit does
    roll = np.deg2rad(20.0) * np.sin(2 * np.pi * 0.11 * tau)
    pitch = np.deg2rad(15.0) * np.sin(2 * np.pi * 0.07 * tau + 1.0)
    yaw = 0.2 * np.sin(2 * np.pi * 0.03 * tau)
    att = Rotation.from_euler("ZYX", np.stack([yaw, pitch, roll], axis=1))  # body -> level
    acc = att.inv().apply(level + [0.0, 0.0, G]) + acc_noise * rng.standard_normal((n, 3))
    steps = (att[:-1].inv() * att[1:]).as_rotvec() * rate  # body-frame rate over each step
    bias = np.radians(np.asarray(bias_dps, dtype=float))
    gyro = np.vstack([steps, steps[-1:]]) + bias + gyro_noise * rng.standard_normal((n, 3))
    # the level frame's heading: the first sample's body x along level x (as accelnav.level sets it)
    x0 = att[0].apply([1.0, 0.0, 0.0])
    turn = Rotation.from_euler("Z", -np.arctan2(x0[1], x0[0]))
    return HandMoved(t, acc, gyro, turn.apply(level), moving, bias)
