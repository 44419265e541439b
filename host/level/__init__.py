"""The level frame: body-frame accelerometer (+ gyroscope, + orientation) in, level-frame acceleration out.

The smoother wants axes that are level with gravity removed; almost every IMU log is not. An
:class:`ImuRecord` holds one recording as the sensor gave it (body frame, gravity in); :func:`level_frame`
turns it into the frame the smoother reads: x and y horizontal in the start's heading, z up, gravity out.

Conventions (stated once, used everywhere): SI units (m/s^2, rad/s, s); a quaternion is (w, x, y, z)
and rotates a body-frame vector into the level frame (v_level = q v_body q*), the level frame being
x-y horizontal, z up (ENU-like; only the heading of the first sample sets where x points).
The attitude comes from x-io's Fusion AHRS (``imufusion``, MIT, a C core) rather than a filter of ours.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from accelnav.errors import UserError

G = 9.80665  # m/s^2, the standard gravity the level frame subtracts


@dataclass(frozen=True)
class ImuRecord:
    """One IMU recording on one clock, as recorded: body frame, gravity included, SI units.

    ``t`` (N,) seconds, strictly increasing; ``acc`` (N, 3) m/s^2; ``gyro`` (N, 3) rad/s or None;
    ``mag`` (N, 3) any consistent unit or None; ``quat`` (N, 4) the device's own orientation (w, x, y, z,
    body -> level, z up) or None; ``source`` says where it came from (a file and its format) and
    ``notes`` what the reader decided (units, conventions, resampling), one line each.
    """

    t: np.ndarray
    acc: np.ndarray
    gyro: np.ndarray | None = None
    mag: np.ndarray | None = None
    quat: np.ndarray | None = None
    source: str = "arrays"
    notes: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=np.float64)
        if t.ndim != 1 or t.size < 2:
            raise UserError(f"{self.source}: an IMU record needs a 1-D time of at least 2 samples, got shape {t.shape}")
        if not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
            raise UserError(f"{self.source}: the IMU record's time must be finite and strictly increasing")
        object.__setattr__(self, "t", t)
        for name, width in (("acc", 3), ("gyro", 3), ("mag", 3), ("quat", 4)):
            v = getattr(self, name)
            if v is None:
                if name == "acc":
                    raise UserError(f"{self.source}: an IMU record needs the accelerometer")
                continue
            a = np.asarray(v, dtype=np.float64)
            if a.shape != (t.size, width):
                raise UserError(f"{self.source}: {name} has shape {a.shape}, expected ({t.size}, {width})")
            if not np.all(np.isfinite(a)):
                raise UserError(f"{self.source}: {name} holds a non-finite value")
            object.__setattr__(self, name, a)

    @property
    def rate(self) -> float:
        """The mean sample rate, Hz."""
        return (self.t.size - 1) / float(self.t[-1] - self.t[0])


@dataclass(frozen=True)
class LevelResult:
    """The levelled recording: ``acc`` (N, 3) m/s^2 in the level frame with gravity removed (x, y
    horizontal in the start's heading, z up); ``quat`` (N, 4) the attitude used (w, x, y, z, body -> level);
    ``method`` which evidence set the attitude; ``leak`` the residual horizontal level leak in m/s^2 where
    the recording proves a rest (NaN when it proves none); ``notes`` one line per decision."""

    t: np.ndarray
    acc: np.ndarray
    quat: np.ndarray
    method: str
    leak: float = float("nan")
    notes: tuple[str, ...] = field(default_factory=tuple)

    def summary(self) -> str:
        leak = "no rest to measure it" if not np.isfinite(self.leak) else f"{self.leak:.3g} m/s^2 at rest"
        return f"levelled {self.t.size} samples by {self.method}; residual level leak {leak}"


def rotate(quat: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate the rows of ``v`` (N, 3) by the unit quaternions ``quat`` (N, 4) (w, x, y, z)."""
    w = quat[:, :1]
    u = quat[:, 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def level_frame(imu: ImuRecord) -> LevelResult:
    """Level ``imu``: the device's own orientation if it has one, else Fusion's AHRS on its gyroscope and
    accelerometer; the heading is turned so the first sample's heading is x. Refuses a record with neither
    a gyroscope nor an orientation (an accelerometer alone cannot tell tilt from acceleration)."""
    if imu.quat is not None:
        quat, method = _unit(imu.quat), "the recording's own orientation"
    elif imu.gyro is not None:
        quat, method = _fusion(imu), "Fusion AHRS on the gyroscope and accelerometer"
    else:
        raise UserError(f"{imu.source}: no gyroscope and no orientation: the level frame cannot be found")
    quat = _start_heading(quat)
    acc = rotate(quat, imu.acc)
    acc[:, 2] -= G
    return LevelResult(imu.t, acc, quat, method)


def _unit(q: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(q, axis=1, keepdims=True)
    if np.any(n < 1e-6):
        raise UserError("an orientation quaternion has zero length")
    return q / n


def _fusion(imu: ImuRecord) -> np.ndarray:
    try:
        import imufusion
    except ImportError as e:  # a core dependency; only a broken install lacks it
        raise UserError("levelling needs the imufusion package: pip install imufusion") from e
    ahrs = imufusion.Ahrs()
    settings = imufusion.AhrsSettings()
    settings.convention = imufusion.CONVENTION_ENU
    settings.sample_rate = round(imu.rate)
    ahrs.set_settings(settings)
    dt = np.diff(imu.t, prepend=imu.t[0] - 1.0 / imu.rate)
    gyro_dps = np.degrees(imu.gyro)
    acc_g = imu.acc / G
    out = np.empty((imu.t.size, 4))
    for i in range(imu.t.size):
        ahrs.set_sample_period(float(dt[i]))
        ahrs.update_no_magnetometer(gyro_dps[i], acc_g[i])
        out[i] = ahrs.get_quaternion()
    return out


def _start_heading(quat: np.ndarray) -> np.ndarray:
    """Turn every attitude about z so that the first sample's body x points along level x (as far as
    it is not vertical)."""
    x0 = rotate(quat[:1], np.array([[1.0, 0.0, 0.0]]))[0]
    yaw = np.arctan2(x0[1], x0[0])
    turn = np.array([np.cos(-yaw / 2), 0.0, 0.0, np.sin(-yaw / 2)])
    w1, x1, y1, z1 = turn
    w2, x2, y2, z2 = quat.T
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=1,
    )
