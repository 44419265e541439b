"""The level frame: body-frame accelerometer (+ gyroscope, + orientation) in, level-frame acceleration out.

The smoother wants axes that are level with gravity removed; almost every IMU log is not. An
:class:`ImuRecord` holds one recording as the sensor gave it (body frame, gravity in); :func:`level_frame`
turns it into the frame the smoother reads: x and y horizontal in the start's heading, z up, gravity out.

Conventions (stated once, used everywhere): SI units (m/s^2, rad/s, s); a quaternion is (w, x, y, z)
and rotates a body-frame vector into the level frame (v_level = q v_body q*), the level frame being
x-y horizontal, z up (ENU-like; only the heading of the first sample sets where x points).

Rests correct the attitude
--------------------------
At a rest the accelerometer reads gravity alone, so tilt and the gyroscope's bias are observable there:

1. **Rests**: given by the caller, or found by the gyroscope-aided detector (accelnav.level.rests: SHOE
   candidates, stillness against the sensor's own noise, the speed a rest would imply, gravity carried by
   the gyroscope).
2. **Gyroscope bias**: its mean over the middle half of the rests still within the sensor's noise (or
   given) for ``BIAS_REST_S`` or more, removed (a foot's stance rolls too much to tell a bias, a standing of
   a second does not; a rest's ends hold the tails of the moves either side). Not measured where rests
   cover more than ``COVER_MAX`` of the record: a detector calling most of a record rest is not trusted.
3. **Attitude between rests**: where the rests are at most ``STRAPDOWN_GAP_S`` apart (a walk, a stop-and-go
   ride), the gyroscope integrated exactly, as a foot-mounted navigator does: between rests the
   accelerometer holds motion, not gravity. Otherwise x-io's Fusion AHRS (``imufusion``, MIT, a C core:
   a proven filter rather than one of ours), whose accelerometer feedback keeps the tilt bounded through
   long moves. On gaitmap's foot walk, Fusion's own first-order gyro update at the swing's 10 rad/s cost
   0.7-2.6 cm per stride (6.7/8.7 against 6.0/6.0 cm with the true rests) against the exact integration,
   both corrected at the same rests (measured with tests/level/test_level_real.py's set-up).
   On mobgap's lower-back walks, standing 3-7 s apart with the walk between, Fusion's feedback on the
   trunk's acceleration cost 2-3 m over a 4 m walk against the gyroscope alone (both levelled at the
   reference standings): hence 10 s, where a 0.05 deg/s bias left after the rests' own is 0.5 deg.
4. **Tilt correction**: each rest, in pieces of ``ANCHOR_S`` at most, turns the attitude about horizontal
   axes so that its mean level-frame specific force is vertical; the turn is interpolated linearly in
   time between the pieces' middles (what a backward pass of the tilt error would do), heading kept.
   ``passes`` > 1 repeats it: a second pass changes the stride error by < 0.03 cm on the foot walk, so
   one is the default.
5. **Leak**: the rms over the rests of the mean horizontal level-frame acceleration over each rest's
   middle half (mid-stance): what gravity still leaks where the body is known still. The rests make it
   small by construction, so a note says what the correction is unsure of between rests too: how far each
   rest's tilt lies from the line through its neighbours' (before correction), in m/s^2 of leak.

Fusion's settings were measured, not chosen by taste: on the foot walk with Fusion alone (its leak at
mid-stance, its strides with the true rests) and on the lower-back walks with Fusion between the reference
standings (distance walked), gain 0.2 with a 20 degree acceleration rejection and a 10 s recovery gave
1.1/1.0 m/s^2, 7.3/8.5 cm and 1.6/0.4/0.04 m against Fusion's defaults' (gain 0.5, no rejection) 1.6/1.3
m/s^2, 8.9/9.5 cm and 2.2/1.1/1.0 m; gains 0.05-0.5 and rejections 10-20 degrees (recovery 2 or 10 s)
tried, none better on all five.

A record without a rest keeps Fusion's attitude alone and says so; its leak is NaN (nothing proves it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from accelnav.errors import UserError
from accelnav.level.quat import integrate, qmul, rotate, rotvec_quat
from accelnav.level.rests import COVER_MAX, G, RestParams, find_rests
from accelnav.level.rests import spans as rest_spans

__all__ = ["G", "ImuRecord", "LevelResult", "RestParams", "find_rests", "level_frame", "quat", "rests", "rotate"]

GAIN = 0.2  # Fusion's gain (its default 0.5): measured, see the module docstring
ACCELERATION_REJECTION = 20.0  # degrees, Fusion's acceleration rejection (its default 0: off)
REJECTION_TIMEOUT_S = 10.0  # s, Fusion's recovery: rejected this long, the accelerometer is trusted again
PASSES = 1  # tilt corrections by the rests
BIAS_REST_S = 1.0  # s, the gyroscope's bias is measured over rests this long (a foot's stance rolls)
STRAPDOWN_GAP_S = 10.0  # s, rests at most this far apart: the gyroscope alone between them
ANCHOR_S = 0.5  # s, a rest corrects the tilt once per piece this long


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
    the recording proves a rest (NaN when it proves none): the rms over the rests of the mean horizontal
    acceleration over each rest's middle half; ``notes`` one line per decision; ``rests`` the rests that
    corrected the attitude (hand them to the smoother: ``accelnav.smooth_run(..., rest=result.rests)``)."""

    t: np.ndarray
    acc: np.ndarray
    quat: np.ndarray
    method: str
    leak: float = float("nan")
    notes: tuple[str, ...] = field(default_factory=tuple)
    rests: np.ndarray | None = None  # (N,) bool, the rests that corrected the attitude (given or found)
    # m/s^2, rms over the inner rests of how far each one's tilt lies from the line through its neighbours'
    # (before correction): the leak the interpolation may leave between rests, which ``leak`` cannot show
    between: float = float("nan")

    def summary(self) -> str:
        if not np.isfinite(self.leak):
            return f"levelled {self.t.size} samples by {self.method}; residual level leak: no rest to measure it"
        # the correction makes the leak small at the rests by construction: the figure between them is the one to act on
        away = (
            f"about {self.between:.3g} m/s^2 between them (a rest's tilt foretold from its neighbours')"
            if np.isfinite(self.between)
            else "unknown between them (fewer than 3 rests to foretell one from its neighbours)"
        )
        done = f"levelled {self.t.size} samples by {self.method}"
        return f"{done}; residual level leak {self.leak:.3g} m/s^2 at the rests, {away}"


def level_frame(
    imu: ImuRecord,
    *,
    rests: np.ndarray | None = None,
    detector: RestParams | None = None,
    gain: float = GAIN,
    acceleration_rejection: float = ACCELERATION_REJECTION,
    rejection_timeout_s: float = REJECTION_TIMEOUT_S,
    passes: int = PASSES,
) -> LevelResult:
    """Level ``imu`` (see the module docstring for the steps and what each keyword changes).

    ``rests``: rests the caller knows, an (N,) bool mask or an (M, 2) array of (start, end) times in
    seconds; None: found by the gyroscope-aided detector (accelnav.level.rests, ``detector``'s thresholds)
    where a gyroscope exists. ``gain``, ``acceleration_rejection`` (degrees) and ``rejection_timeout_s``:
    Fusion's settings. ``passes``: how many times the rests correct the tilt (0: Fusion's attitude alone).
    Refuses a record with neither a gyroscope nor an orientation (an accelerometer alone cannot tell tilt
    from acceleration)."""
    if imu.quat is None and imu.gyro is None:
        raise UserError(f"{imu.source}: no gyroscope and no orientation: the level frame cannot be found")
    if not (isinstance(passes, int) and 0 <= passes <= 5):
        raise UserError(f"level_frame passes: got {passes!r}; accepted: an integer from 0 to 5")
    notes: list[str] = []
    n = imu.t.size
    still = None  # the rests that prove stillness (None: given, the caller vouches for them)
    if rests is not None:
        mask, said = _given_rests(rests, imu.t), "given"
    elif imu.gyro is not None:
        finding = find_rests(imu.t, imu.acc, imu.gyro, detector or RestParams())
        mask, still, said = finding.mask, finding.still, "found by the gyroscope and accelerometer"
        notes += finding.notes
    else:
        mask, said = np.zeros(n, dtype=bool), ""
    found = rest_spans(mask)
    if said:
        notes.insert(0, f"{len(found)} rests {said}, {mask.mean():.0%} of the record")
    else:
        notes.append("no gyroscope to find rests by, none given: the orientation as recorded")
    anchors = _anchors(found, imu.rate)
    if imu.quat is not None:
        quat, method = _unit(imu.quat), "the recording's own orientation"
    else:
        bias = _gyro_bias(imu, mask, still, notes)
        gap = _longest_gap(anchors, imu.t)
        if passes and gap <= STRAPDOWN_GAP_S:
            quat = _strapdown(imu, bias, anchors[0])
            method = "the gyroscope integrated between rests"
            notes.append(f"rests at most {gap:.3g} s apart (<= {STRAPDOWN_GAP_S:g} s): the gyroscope alone between")
        else:
            quat = _fusion(imu, bias, gain, acceleration_rejection, rejection_timeout_s)
            method = "Fusion AHRS on the gyroscope and accelerometer"
            if anchors and passes:
                notes.append(f"rests up to {gap:.3g} s apart (> {STRAPDOWN_GAP_S:g} s): Fusion's attitude between them")
    between = float("nan")
    if anchors and passes:
        between = _between(quat, imu.acc, found, imu.t)
        if np.isfinite(between):
            notes.append(
                f"between rests: a rest's tilt foretold from its two neighbours' misses by {between:.3g} m/s^2 "
                f"rms over {len(found) - 2} rests (the leak the interpolation may leave between them)"
            )
        for _ in range(passes):
            quat = _tilt_corrected(quat, imu.acc, anchors, imu.t)
        method += f", tilt corrected at {len(found)} rests"
    elif not found:
        notes.append("no rest: the tilt is not corrected, the leak cannot be measured")
    quat = _start_heading(quat)
    acc = rotate(quat, imu.acc)
    acc[:, 2] -= G
    leak = _leak(acc, found)
    if np.isfinite(leak):
        notes.append(f"leak: rms over {len(found)} rests of the mean horizontal acceleration in their middle half")
    return LevelResult(imu.t, acc, quat, method, leak, tuple(notes), mask, between)


def _given_rests(rests, t: np.ndarray) -> np.ndarray:
    """An (N,) bool mask from a mask or from (start, end) times in seconds."""
    r = np.asarray(rests)
    if r.dtype == bool:
        if r.shape != t.shape:
            raise UserError(f"rests: a mask of shape {r.shape}, the record has {t.size} samples")
        return r.copy()
    try:
        r = np.asarray(rests, dtype=np.float64)
    except (TypeError, ValueError):
        raise UserError("rests: expected an (N,) bool mask or (start, end) times in seconds") from None
    if r.size == 0:
        return np.zeros(t.size, dtype=bool)
    if r.ndim != 2 or r.shape[1] != 2 or not np.all(np.isfinite(r)) or np.any(r[:, 1] < r[:, 0]):
        raise UserError("rests: expected an (N,) bool mask or rows of (start, end) times in seconds, start <= end")
    mask = np.zeros(t.size, dtype=bool)
    for a, b in r:
        mask[np.searchsorted(t, a) : np.searchsorted(t, b, side="right")] = True
    return mask


def _longest_gap(anchors: list[tuple[int, int]], t: np.ndarray) -> float:
    """The longest time the attitude goes without an anchor: between anchors, before the first, after the last."""
    if not anchors:
        return float("inf")
    mids = np.array([0.5 * (t[a] + t[b - 1]) for a, b in anchors])
    return float(max(mids[0] - t[0], t[-1] - mids[-1], np.diff(mids).max(initial=0.0)))


def _strapdown(imu: ImuRecord, bias: np.ndarray, first: tuple[int, int]) -> np.ndarray:
    """The gyroscope integrated exactly (accelnav.level.quat.integrate), from a start levelled by the first
    anchor's gravity."""
    q = integrate(imu.t, imu.gyro - bias)
    a, b = first
    f = rotate(q[a:b], imu.acc[a:b]).mean(axis=0)  # gravity at the first anchor, in the start's frame
    horiz = np.hypot(f[0], f[1])
    angle = np.arctan2(horiz, f[2])
    k = angle / horiz if horiz > 0 else 0.0
    return qmul(rotvec_quat(np.array([[f[1] * k, -f[0] * k, 0.0]])), q)


def _gyro_bias(imu: ImuRecord, mask: np.ndarray, still: np.ndarray | None, notes: list[str]) -> np.ndarray:
    """The gyroscope's mean over the middle half of the rests that prove stillness (within the sensor's noise,
    found) or are given, lasting ``BIAS_REST_S`` at least (a foot's short stances roll); none where rests
    cover more than ``COVER_MAX`` of the record (a detector calling most of a record rest is not
    to be trusted with a bias)."""
    if mask.mean() > COVER_MAX:
        notes.append(
            f"gyro bias not measured: rests cover {mask.mean():.0%} of the record (> {COVER_MAX:.0%}), "
            "too much to trust them still"
        )
        return np.zeros(3)
    kind = "given" if still is None else "still within the sensor's noise"
    proven = mask if still is None else mask & still
    long = [(a, b) for a, b in rest_spans(proven) if b - a >= BIAS_REST_S * imu.rate]
    if not long:
        notes.append(f"gyro bias not measured: no rest {kind} for {BIAS_REST_S:g} s")
        return np.zeros(3)
    sel = np.concatenate([np.arange(a + (b - a) // 4, b - (b - a) // 4) for a, b in long])  # a move's ends out
    bias = imu.gyro[sel].mean(axis=0)
    deg = np.degrees(bias)
    secs = sum(b - a for a, b in long) / imu.rate
    notes.append(
        f"gyro bias ({deg[0]:.3g}, {deg[1]:.3g}, {deg[2]:.3g}) deg/s measured over {len(long)} "
        f"rest{'s' if len(long) > 1 else ''} {kind} for {BIAS_REST_S:g} s or more ({secs:.3g} s, their middle "
        "half), removed"
    )
    return bias


def _anchors(found: list[tuple[int, int]], rate: float) -> list[tuple[int, int]]:
    """The rests' middle halves cut into pieces of at most ``ANCHOR_S``: each corrects the tilt at its middle.
    A found rest's edges are where it may run into motion (a hand easing a phone into a move: 0.4 s of it
    taken as rest leaned the tilt by the move's acceleration, 0.8 m off over a 6 s move), so, as the leak,
    the tilt is read from the middle half."""
    step = max(1, int(round(ANCHOR_S * rate)))
    out = []
    for a0, b0 in found:
        a, b = a0 + (b0 - a0) // 4, b0 - (b0 - a0) // 4
        if b - a <= step:
            out.append((a, b))
            continue
        edges = np.linspace(a, b, -(-(b - a) // step) + 1).round().astype(int)
        out += [(int(lo), int(hi)) for lo, hi in zip(edges[:-1], edges[1:], strict=True) if hi > lo]
    return out


def _tilt_vectors(quat: np.ndarray, acc: np.ndarray, pieces: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Per piece, the small rotation (phi_x, phi_y) taking its mean level-frame specific force onto +z, and
    the piece's (lo, hi) sample bounds as arrays."""
    f = rotate(quat, acc)
    c = np.concatenate([np.zeros((1, 3)), np.cumsum(f, axis=0)])
    lo = np.array([a for a, _ in pieces])
    hi = np.array([b for _, b in pieces])
    fm = (c[hi] - c[lo]) / (hi - lo)[:, None]
    # the rotation taking fm onto +z: about fm x z, by the angle between them
    horiz = np.hypot(fm[:, 0], fm[:, 1])
    angle = np.arctan2(horiz, fm[:, 2])
    scale = np.divide(angle, horiz, out=np.zeros_like(angle), where=horiz > 0)
    return np.column_stack([fm[:, 1] * scale, -fm[:, 0] * scale]), np.stack([lo, hi])


def _between(quat: np.ndarray, acc: np.ndarray, found: list[tuple[int, int]], t: np.ndarray) -> float:
    """rms over the rests but the first and last of how far each rest's tilt (before correction) is from the
    line through its neighbours', as g sin(angle) in m/s^2: NaN with fewer than 3 rests."""
    if len(found) < 3:
        return float("nan")
    phi, (lo, hi) = _tilt_vectors(quat, acc, found)
    tm = 0.5 * (t[lo] + t[hi - 1])
    w = ((tm[1:-1] - tm[:-2]) / (tm[2:] - tm[:-2]))[:, None]
    miss = phi[1:-1] - ((1 - w) * phi[:-2] + w * phi[2:])
    return float(G * np.sqrt(np.mean(np.sum(np.sin(miss) ** 2, axis=1))))


def _tilt_corrected(quat: np.ndarray, acc: np.ndarray, anchors: list[tuple[int, int]], t: np.ndarray) -> np.ndarray:
    """``quat`` turned about horizontal axes so that the mean level-frame specific force of every anchor is
    vertical, the turn interpolated linearly in time between anchors' middles (held before the first and
    after the last): what a backward smoothing pass of the tilt error between rests would do. Heading kept."""
    at, (lo, hi) = _tilt_vectors(quat, acc, anchors)
    tm = 0.5 * (t[lo] + t[hi - 1])
    phi = np.column_stack([np.interp(t, tm, at[:, 0]), np.interp(t, tm, at[:, 1]), np.zeros(t.size)])
    return qmul(rotvec_quat(phi), quat)


def _leak(acc: np.ndarray, found: list[tuple[int, int]]) -> float:
    """rms over the rests of the mean horizontal level-frame acceleration over each rest's middle half."""
    if not found:
        return float("nan")
    c = np.concatenate([np.zeros((1, 2)), np.cumsum(acc[:, :2], axis=0)])
    lo = np.array([a + (b - a) // 4 for a, b in found])
    hi = np.array([max(b - (b - a) // 4, lo_ + 1) for (a, b), lo_ in zip(found, lo, strict=True)])
    m = (c[hi] - c[lo]) / (hi - lo)[:, None]
    return float(np.sqrt(np.mean(np.sum(m * m, axis=1))))


def _unit(q: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(q, axis=1, keepdims=True)
    if np.any(n < 1e-6):
        raise UserError("an orientation quaternion has zero length")
    return q / n


def _fusion(imu: ImuRecord, bias: np.ndarray, gain: float, rejection: float, timeout_s: float) -> np.ndarray:
    try:
        import imufusion
    except ImportError as e:  # a core dependency; only a broken install lacks it
        raise UserError("levelling needs the imufusion package: pip install imufusion") from e
    for name, v in (("gain", gain), ("acceleration_rejection", rejection), ("rejection_timeout_s", timeout_s)):
        if not (np.isfinite(v) and v >= 0):
            raise UserError(f"level_frame {name}: got {v}; accepted: a number >= 0")
    ahrs = imufusion.Ahrs()
    settings = imufusion.AhrsSettings()
    settings.convention = imufusion.CONVENTION_ENU
    settings.sample_rate = round(imu.rate)
    settings.gain = float(gain)
    settings.acceleration_rejection = float(rejection)
    settings.rejection_timeout = int(round(timeout_s * imu.rate))
    ahrs.set_settings(settings)
    dt = np.diff(imu.t, prepend=imu.t[0] - 1.0 / imu.rate)
    gyro_dps = np.degrees(imu.gyro - bias)
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
    turn = np.array([[np.cos(-yaw / 2), 0.0, 0.0, np.sin(-yaw / 2)]])
    return qmul(turn, quat)
