"""A tilted, turning phone that moves a known distance, written as each phone logger app writes it.

The truth: 3 s still, a 6 s minimum-jerk move of MOVE metres in the world's x and y, shaken by the hand
(SHAKE at SHAKE_HZ along x and y), while the phone turns
TURN about the vertical, 3 s still; tilted TILT about its own x axis throughout, so its x axis stays
horizontal and its heading at the start (0) makes the level frame the world frame. The sensors: specific
force (gravity in, Android's sign) and body rates with a little seeded noise, the gyroscope on a clock 3 ms
behind the accelerometer's and the orientation at half the rate 1 ms ahead, as loggers give them.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from support.quaternions import about, conj

from accelnav.level import G, rotate
from accelnav.level.quat import qmul

RATE = 200.0
MOVE = np.array([1.0, 0.5])  # metres along the world's x and y
TURN = np.radians(90.0)
TILT = np.radians(20.0)
STILL_S, MOVE_S = 3.0, 6.0
SHAKE, SHAKE_HZ = 0.0015, (5.0, 4.0)  # m; Hz along x and y: 1.5 and 0.9 m/s^2
EPOCH_NS = 1_764_331_200_000_000_000  # 2025-11-28 12:00 UTC, as Sensor Logger's time column counts


@dataclass(frozen=True)
class Phone:
    t: np.ndarray  # accelerometer clock, s from the start
    f: np.ndarray  # specific force in the device's axes, m/s^2, Android's sign
    grav: np.ndarray  # gravity's part of it (Android's Gravity sensor)
    tg: np.ndarray  # gyroscope clock
    gyro: np.ndarray  # rad/s
    tq: np.ndarray  # orientation clock
    quat: np.ndarray  # device -> world (w, x, y, z)
    a_level: np.ndarray  # the truth: level-frame acceleration, gravity out
    r_level: np.ndarray  # and position


def _profile(t: np.ndarray):
    """(s, s', s'') of the minimum-jerk move over [STILL_S, STILL_S + MOVE_S]."""
    tau = np.clip((t - STILL_S) / MOVE_S, 0.0, 1.0)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / MOVE_S
    dds = (60 * tau - 180 * tau**2 + 120 * tau**3) / MOVE_S**2
    return s, ds, dds


def _attitude(t: np.ndarray):
    s, ds, _ = _profile(t)
    q = qmul(about(2, TURN * s), about(0, np.full(t.size, TILT)))  # yaw after the tilt: device -> world
    w_world = np.column_stack([np.zeros(t.size), np.zeros(t.size), TURN * ds])
    return q, rotate(conj(q), w_world)


def _fade(tau: np.ndarray, edge: float = 0.1):
    """(w, w', w'') of a window rising from 0 to 1 over the first ``edge`` of [0, 1] and falling over the last,
    each by the minimum-jerk step (so the shake starts and ends with no velocity)."""
    w, dw, ddw = np.ones_like(tau), np.zeros_like(tau), np.zeros_like(tau)
    for x, sign in ((tau / edge, 1.0), ((1.0 - tau) / edge, -1.0)):
        on = x < 1.0
        xo = np.clip(x, 0.0, 1.0)
        w = np.where(on, 10 * xo**3 - 15 * xo**4 + 6 * xo**5, w)
        dw = np.where(on, sign * (30 * xo**2 - 60 * xo**3 + 30 * xo**4) / edge, dw)
        ddw = np.where(on, (60 * xo - 180 * xo**2 + 120 * xo**3) / edge**2, ddw)
    return w, dw, ddw


def _shake(t: np.ndarray, hz: float):
    """(position, acceleration) of the hand's shake at ``hz`` while the phone moves, SHAKE m, faded in and out so
    that it starts and ends at rest: the rest detector sees a moving phone, not a smooth cruise."""
    tau = np.clip((t - STILL_S) / MOVE_S, 0.0, 1.0)
    k = 2 * np.pi * hz * MOVE_S
    u, du, ddu = np.sin(k * tau), k * np.cos(k * tau), -(k**2) * np.sin(k * tau)
    w, dw, ddw = _fade(tau)
    inside = (t > STILL_S) & (t < STILL_S + MOVE_S)
    return SHAKE * u * w, inside * SHAKE * (ddu * w + 2 * du * dw + u * ddw) / MOVE_S**2


def phone(seed: int = 1, duration: float = 2 * STILL_S + MOVE_S) -> Phone:
    rng = np.random.default_rng(seed)
    n = int(round(duration * RATE)) + 1
    t = np.arange(n) / RATE
    s, _, dds = _profile(t)
    (rx, ax), (ry, ay) = _shake(t, SHAKE_HZ[0]), _shake(t, SHAKE_HZ[1])
    a_level = np.column_stack([MOVE[0] * dds + ax, MOVE[1] * dds + ay, np.zeros(n)])
    r_level = np.column_stack([MOVE[0] * s + rx, MOVE[1] * s + ry, np.zeros(n)])
    q, _ = _attitude(t)
    f = rotate(conj(q), a_level + [0.0, 0.0, G]) + rng.normal(0, 0.02, (n, 3))
    grav = rotate(conj(q), np.tile([0.0, 0.0, G], (n, 1)))
    tg = t - 0.003
    _, gyro = _attitude(tg)
    gyro = gyro + rng.normal(0, 0.002, gyro.shape)
    tq = t[::2] - 0.001  # half the rate
    quat, _ = _attitude(tq)
    return Phone(t, f, grav, tg, gyro, tq, quat, a_level, r_level)


def still(duration: float, seed: int = 2) -> Phone:
    """The phone lying still, tilted TILT, for ``duration`` s (a stationary recording for the bias fit)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration * RATE)) + 1) / RATE
    q = about(0, np.full(t.size, TILT))
    grav = rotate(conj(q), np.tile([0.0, 0.0, G], (t.size, 1)))
    zero = np.zeros((t.size, 3))
    f = grav + rng.normal(0, 0.02, zero.shape)
    return Phone(t, f, grav, t - 0.003, rng.normal(0, 0.002, zero.shape), t[::2] - 0.001, q[::2], zero, zero)


def jittered(p: Phone, jitter: float, seed: int = 0) -> Phone:
    """``p`` with its accelerometer's stamps off their grid by up to ``jitter`` s (as a phone's sensor events
    arrive), the specific force taken at those times."""
    rng = np.random.default_rng(seed)
    t = p.t + rng.uniform(-jitter, jitter, p.t.size)
    t = np.maximum.accumulate(t) + np.arange(t.size) * 1e-9  # still increasing
    f, _, q = truth_at(t)
    f = f + rng.normal(0, 0.02, f.shape)
    grav = rotate(conj(q), np.tile([0.0, 0.0, G], (t.size, 1)))
    return Phone(t, f, grav, p.tg, p.gyro, p.tq, p.quat, p.a_level, p.r_level)


def _csv(header: list[str], cols: list[np.ndarray], fmt: str = "%.9g") -> str:
    """``cols`` under ``header``; an integer column (Sensor Logger's nanoseconds) written whole."""
    lines = [",".join(header)]
    cells = [[str(v) for v in c] if np.asarray(c).dtype.kind in "iu" else [fmt % v for v in c] for c in cols]
    lines += [",".join(row) for row in zip(*cells, strict=True)]
    return "\n".join(lines) + "\n"


def _zip(path: Path, files: dict[str, str]) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, text in files.items():
            z.writestr(zipfile.ZipInfo(name, (2025, 11, 28, 12, 0, 0)), text, zipfile.ZIP_DEFLATED)  # the same bytes
    return path


def sensor_logger_files(p: Phone, platform: str = "android") -> dict[str, str]:
    """Sensor Logger's CSVs: per sensor ``time`` (Unix ns), ``seconds_elapsed``, then ``z, y, x``; Android
    writes TotalAcceleration.csv, iOS Accelerometer.csv (gravity removed) and Gravity.csv with CoreMotion's
    sign; Orientation.csv ``qz, qy, qx, qw, roll, pitch, yaw``; Metadata.csv names the platform."""

    def clock(t):
        return [np.round(EPOCH_NS + t * 1e9).astype(np.int64), t + 0.25]

    def xyz(v):
        return [v[:, 2], v[:, 1], v[:, 0]]

    head = ["time", "seconds_elapsed", "z", "y", "x"]
    files = {}
    if platform == "android":
        files["TotalAcceleration.csv"] = _csv(head, [*clock(p.t), *xyz(p.f)], "%.10g")
    else:
        sign = -1.0  # CoreMotion's: an inertial force
        files["Accelerometer.csv"] = _csv(head, [*clock(p.t), *xyz(sign * (p.f - p.grav))], "%.10g")
        files["Gravity.csv"] = _csv(head, [*clock(p.t), *xyz(sign * p.grav)], "%.10g")
    files["Gyroscope.csv"] = _csv(head, [*clock(p.tg), *xyz(p.gyro)], "%.10g")
    q = p.quat
    files["Orientation.csv"] = _csv(
        ["time", "seconds_elapsed", "qz", "qy", "qx", "qw", "roll", "pitch", "yaw"],
        [*clock(p.tq), q[:, 3], q[:, 2], q[:, 1], q[:, 0], *np.zeros((3, len(q)))],
        "%.12g",
    )
    files["Metadata.csv"] = (
        "version,device name,recording time,platform,appVersion\n"
        f"3,Pixel 7,2025-11-28_12-00-00,{'ios' if platform == 'ios' else 'android'},1.40.1\n"
    )
    return files


def sensor_logger_zip(path: Path, p: Phone, platform: str = "android", drop: tuple[str, ...] = ()) -> Path:
    return _zip(path, {k: v for k, v in sensor_logger_files(p, platform).items() if k not in drop})


def phyphox_zip(path: Path, p: Phone) -> Path:
    """phyphox's export of its accelerometer (with g) and gyroscope: a CSV each, ``Time (s)`` from the start."""

    def absolute(v):
        return np.linalg.norm(v, axis=1)

    acc = _csv(['"Time (s)"', '"Acceleration x (m/s^2)"', '"Acceleration y (m/s^2)"', '"Acceleration z (m/s^2)"',
                '"Absolute acceleration (m/s^2)"'], [p.t, *p.f.T, absolute(p.f)], "%.9E")  # fmt: skip
    gyro = _csv(['"Time (s)"', '"Gyroscope x (rad/s)"', '"Gyroscope y (rad/s)"', '"Gyroscope z (rad/s)"',
                 '"Absolute (rad/s)"'], [p.tg + 0.003, *p.gyro.T, absolute(p.gyro)], "%.9E")  # fmt: skip
    return _zip(path, {"Accelerometer.csv": acc, "Gyroscope.csv": gyro, "meta/device.csv": "property,value\n"})


def physics_toolbox_csv(path: Path, p: Phone) -> Path:
    """Physics Toolbox Sensor Suite's multi-record CSV: a clock ``HH:MM:SS:mmm``, the g-force in g, the linear
    acceleration, the gyroscope in rad/s, Euler angles in degrees."""
    start = 12 * 3600 + 34 * 60 + 56.0
    lines = ["time,gFx,gFy,gFz,ax,ay,az,wx,wy,wz,Azimuth,Pitch,Roll"]
    lin = p.f - p.grav
    for k, tk in enumerate(p.t):
        sec = start + tk
        h, rem = divmod(sec, 3600)
        m, s = divmod(rem, 60)
        clock = f"{int(h):02d}:{int(m):02d}:{int(s):02d}:{int(round((s - int(s)) * 1000)) % 1000:03d}"
        vals = [*(p.f[k] / G), *lin[k], *p.gyro[min(k, len(p.gyro) - 1)], 0.0, 0.0, 0.0]
        lines.append(clock + "," + ",".join(f"{v:.6f}" for v in vals))
    path.write_text("\n".join(lines) + "\n")
    return path


def sensorlog_csv(path: Path, p: Phone) -> Path:
    """SensorLog's one-row-per-sample CSV, every sensor with its own clock since reboot; the accelerometer in g
    with CoreMotion's sign; the motion quaternion device -> reference (x, y, z, w)."""
    boot = 5000.0
    head = ["loggingTime(txt)", "loggingSample(N)", "accelerometerTimestamp_sinceReboot(s)",
            "accelerometerAccelerationX(G)", "accelerometerAccelerationY(G)", "accelerometerAccelerationZ(G)",
            "gyroTimestamp_sinceReboot(s)", "gyroRotationX(rad/s)", "gyroRotationY(rad/s)", "gyroRotationZ(rad/s)",
            "motionTimestamp_sinceReboot(s)", "motionYaw(rad)", "motionRoll(rad)", "motionPitch(rad)",
            "motionQuaternionX(R)", "motionQuaternionY(R)", "motionQuaternionZ(R)", "motionQuaternionW(R)"]  # fmt: skip
    rows = [",".join(head)]
    acc = -p.f / G
    for k, tk in enumerate(p.t):
        j = min(k // 2, len(p.tq) - 1)  # the motion sensor at half the rate: its last value repeated
        q = p.quat[j]
        vals = [boot + tk, *acc[k], boot + p.tg[k], *p.gyro[k], boot + p.tq[j], 0.0, 0.0, 0.0, q[1], q[2], q[3], q[0]]
        rows.append(f"2025-11-28T12:00:{tk:06.3f}+00:00,{k}," + ",".join(f"{v:.9f}" for v in vals))
    path.write_text("\n".join(rows) + "\n")
    return path


def generic_csv(path: Path, p: Phone, quat: bool = False) -> Path:
    """A generic IMU CSV on one clock: ``t, ax_g, ay_g, az_g, gx_dps, gy_dps, gz_dps`` (and ``qw, qx, qy, qz``)."""
    gyro = np.column_stack([np.interp(p.t, p.tg, p.gyro[:, j]) for j in range(3)])
    head = ["t", "ax_g", "ay_g", "az_g", "gx_dps", "gy_dps", "gz_dps"]
    cols = [p.t, *(p.f / G).T, *np.degrees(gyro).T]
    if quat:
        q, _ = _attitude(p.t)
        head += ["qw", "qx", "qy", "qz"]
        cols += list(q.T)
    path.write_text(_csv(head, cols, "%.10g"))
    return path


def truth_at(t: np.ndarray):
    """(specific force without noise, body rates, attitude) at times ``t`` [s from the start]."""
    s, _, dds = _profile(t)
    (_, ax), (_, ay) = _shake(t, SHAKE_HZ[0]), _shake(t, SHAKE_HZ[1])
    q, w = _attitude(t)
    a = np.column_stack([MOVE[0] * dds + ax, MOVE[1] * dds + ay, np.full(t.size, G)])
    return rotate(conj(q), a), w, q


def displacement(t: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Double integration (trapezoids) from rest, the velocity's drift removed so it ends at rest as the truth
    does: the position a levelled record gives with its two rests known."""
    dt = np.diff(t)[:, None]
    v = np.vstack([np.zeros((1, a.shape[1])), np.cumsum(0.5 * (a[1:] + a[:-1]) * dt, axis=0)])
    v -= np.outer((t - t[0]) / (t[-1] - t[0]), v[-1])
    return np.vstack([np.zeros((1, a.shape[1])), np.cumsum(0.5 * (v[1:] + v[:-1]) * dt, axis=0)])
