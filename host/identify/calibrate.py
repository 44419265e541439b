"""Static multi-position calibration: zero-g offset, sensitivity and cross-axis terms from still poses.

Model (per sensing axis i, accelerations in m/s^2 as converted with the model's current calibration):

    m_i = o_i + s_i g_i + sum_{k != i} c_ik g_k + noise

where g is gravity's projection on the part's axes in the pose (axis i reads +1 g pointing up), o_i the
zero-g offset (everything constant the conversion gets wrong, bias at that moment included), s_i the
sensitivity relative to the model's, c_ik the cross-axis sensitivity to axis k.

Poses
-----
Found automatically: a sample is still when, on every axis, the standard deviation over a ``window_s`` window
is at most ``STILL_K`` times that axis's typical (median) window deviation, and the means of the two
adjacent windows around it differ by at most ``LEVEL_K`` standard errors (a slow turn through a small
angle, as between two tilted poses, can stay below the spread test on every axis); runs of still samples lasting
``min_pose_s`` or longer (less half a window at each end) are poses. A pose's mean is its reading; its
standard error comes from the spread of 0.5 s block means, taken from their successive differences (which
allows for short-range correlation of the noise and is not inflated by a creep) plus an allowance for the
read-out's quantisation: with analog noise of sd sigma (the model's: density and bandwidth) on a step q, the
mean of rounded samples is off by at most (q/pi) exp(-2 pi^2 sigma^2 / q^2) (the first harmonic of the
rounding error; the default ADXL250's 12-bit ADC gives up to 0.07 step = 2.2 mg), counted as a sinusoid of
that amplitude at a random phase (variance b^2/2). A turn starts slowly (1 - cos), so a pose is also
trimmed to the samples whose 0.5 s mean stays within 4 standard errors of the pose's central level. A pose
whose two halves differ by more than 2 mg and 6 standard errors is refused as not still.

Method, chosen from the poses (:func:`calibrate`)
------------------------------------------------
*Known orientations*, when every pose is aligned: every axis within ``ALIGN_TOL_G`` of +1, 0 or -1 g, at
most one axis at +-1 g (the six-position test on a cube; with a 2-axis part, +-x, +-y and flat). Gravity's
projection on each axis is then known in every pose, and each axis is a linear fit (below).

*Gravity magnitude*, when some pose is tilted and the part has 3 axes: the orientations are unknown, but
in every still pose the calibrated reading has the length of gravity (the classic ellipsoid fit):

    | N^-1 diag(1/s) (m - o) | = G0

with o the offsets, s the sensitivities (relative to the model's) and N's rows the unit sensing directions
in a frame tied to the axes (x = (1, 0, 0), y = (p, sqrt(1 - p^2), 0), z = (q, r, sqrt(1 - q^2 - r^2))):
a rotation of the whole part is not observable, so of the cross-axis terms only the three angles between
the axes are (n_i . n_k, about c_ik + c_ki of the linear model), fitted when there are
``MIN_POSES_ANGLES`` poses or more. Weighted nonlinear least squares (Levenberg-Marquardt) of |.| - G0,
each pose weighted by the variance of its residual from its axes' noise and rounding allowance (the
rounding errors are independent here: the poses' levels differ); the weights are re-evaluated at the
estimate and the fit repeated. Intervals from the Jacobian (observed information), scaled by chi2/dof
with Student's t as below. It needs ``MIN_POSES_ANY`` poses or more (6 unknowns, one equation per pose),
and poses spread in direction: refused, saying which, when they all lie near one direction or one plane,
when some axis is never read far from 0 g or its readings span too little, or when an axis's sensitivity
comes out known to worse than ``SCALE_SE_MAX`` (offset ``OFFSET_SE_MAX_G``). It takes the local gravity
as G0 (the standard value; local gravity differs by up to +-0.3 %, which would show in the sensitivities,
as it does in the known-orientation method).

With a 2-axis part tilted poses are refused: gravity's third component is not measured, so neither |g|
nor a tilt gives the in-plane level of a tilted pose.

What is identifiable (known orientations)
-----------------------------------------
Offset and sensitivity of axis i need i read at two different levels (+1 and -1 g, or +-1 and 0 g).
A cross term c_ik needs axis k at +-1 g in poses where i is at 0 and enough poses left over (the
design matrix of axis i keeps full column rank with at least one degree of freedom). With a 2-axis part
the out-of-plane component is never known (flat face up and face down read the same), so cross-axis
sensitivity to it is not identifiable.

Each axis is a generalised least-squares fit over the poses: the noise of the pose means is independent,
the rounding error is shared by poses at the same level of that axis (fully correlated). Its 95 % intervals are normal
(1.96 se); when the fit has 3 or more degrees of freedom and the residuals exceed what the standard errors
explain (chi^2/dof > 1), the covariance is scaled by chi^2/dof and the intervals use Student's t with dof
degrees of freedom (a bias that drifts between poses shows up this way).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from accelnav.lazy import lazy_module
from accelnav.model.load import G0

optimize = lazy_module("scipy.optimize")
stats = lazy_module("scipy.stats")

WINDOW_S = 0.5
MIN_POSE_S = 3.0
STILL_K = 3.0
LEVEL_K = 6.0  # adjacent windows' means further apart than this many standard errors: the part is turning
ALIGN_TOL_G = 0.2
MIN_POSES = 4
MAX_POSES = 500  # the fit's covariance of the pose means is poses x poses
DRIFT_MAX_G = 2e-3  # a pose whose halves differ by more than this and 6 standard errors is not still
BLOCK_S = 0.5


class CalibrationError(ValueError):
    """The recording cannot be calibrated (one line, says why and where)."""


@dataclass(frozen=True)
class Pose:
    i0: int  # first sample
    i1: int  # one past the last
    t0: float
    t1: float
    mean: np.ndarray  # (axes,) m/s^2
    se: np.ndarray  # (axes,) m/s^2, standard error of the mean from the noise
    quant: np.ndarray  # (axes,) m/s^2, amplitude of the possible rounding error of the mean
    level: np.ndarray  # (axes,) in g: -1, 0 or +1


@dataclass(frozen=True)
class AxisCal:
    name: str
    offset: float  # m/s^2
    scale: float  # relative to the model's sensitivity
    cross: dict[str, float]  # axis name -> c_ik (dimensionless)
    se: dict[str, float]  # "offset", "scale", and cross axis names
    ci95: dict[str, tuple[float, float]]
    not_identified: tuple[str, ...]  # terms that the poses cannot separate, with the reason
    chi2: float
    dof: int
    residual_rms: float  # m/s^2
    scaled: bool  # covariance scaled by chi2/dof


ALIGNED = "known orientations (aligned poses: each axis at +1, 0 or -1 g)"
GRAVITY = "gravity magnitude (poses in any orientation: |gravity| = 1 g in each)"


@dataclass(frozen=True)
class Calibration:
    poses: tuple[Pose, ...]
    axes: tuple[AxisCal, ...]
    method: str = ALIGNED
    pairs: tuple = ()  # gravity method with enough poses: PairCal per pair of axes


def _moving_mean(x: np.ndarray, w: int) -> np.ndarray:
    c1 = np.concatenate(([0.0], np.cumsum(x)))
    m = (c1[w:] - c1[:-w]) / w
    pad_l = (w - 1) // 2
    return np.concatenate((np.full(pad_l, m[0]), m, np.full(len(x) - len(m) - pad_l, m[-1])))


def _moving_std(x: np.ndarray, w: int) -> np.ndarray:
    """Standard deviation over a centred window of w samples (edges use the nearest full window)."""
    c1 = np.concatenate(([0.0], np.cumsum(x)))
    c2 = np.concatenate(([0.0], np.cumsum(x * x)))
    m = (c1[w:] - c1[:-w]) / w
    v = np.maximum((c2[w:] - c2[:-w]) / w - m * m, 0.0)
    sd = np.sqrt(v)
    pad_l = (w - 1) // 2
    return np.concatenate((np.full(pad_l, sd[0]), sd, np.full(len(x) - len(sd) - pad_l, sd[-1])))


def quantisation_bias(sd: float, step: float) -> float:
    """Largest error of the mean of rounded samples: (q/pi) exp(-2 pi^2 sd^2 / q^2)."""
    if step <= 0:
        return 0.0
    return step / math.pi * math.exp(-2.0 * math.pi**2 * (sd / step) ** 2)


def detect_poses(
    accel: np.ndarray,
    rate_hz: float,
    *,
    steps: np.ndarray | None = None,
    noise_sd: float | None = None,
    window_s: float = WINDOW_S,
    min_pose_s: float = MIN_POSE_S,
) -> list[Pose]:
    """Still poses in ``accel`` (n, axes) [m/s^2].

    ``steps`` (axes,) is the read-out's step in m/s^2 and ``noise_sd`` the analog noise in front of it
    (m/s^2; from the model's noise density and bandwidth). Without ``noise_sd`` the noise is estimated per
    pose from the samples' variance less q^2/12, which is poor when the noise is below a step: the
    variance of coarsely rounded samples depends on where the level falls between two codes.
    """
    accel = np.asarray(accel, dtype=np.float64)
    n, m = accel.shape
    w = max(3, int(round(window_s * rate_hz)))
    if n < 2 * w:
        raise CalibrationError(f"{n} samples are too few: a pose needs at least {min_pose_s:g} s")
    sd = np.column_stack([_moving_std(accel[:, j], w) for j in range(m)])
    floor = np.array([max(1e-6 * G0, 0.5 * (steps[j] if steps is not None else 0.0)) for j in range(m)])
    thr = STILL_K * np.maximum(np.median(sd, axis=0), floor)
    mm = np.column_stack([_moving_mean(accel[:, j], w) for j in range(m)])
    # a slow turn through a small angle can keep every axis's spread below thr: also not still where the
    # means of the two adjacent windows differ by more than LEVEL_K standard errors of their difference
    h = w // 2
    step_tol = LEVEL_K * math.sqrt(2.0) * np.maximum(np.median(sd, axis=0), floor) / math.sqrt(w)
    jump = np.zeros_like(mm)
    jump[h : n - h] = np.abs(mm[2 * h :] - mm[: n - 2 * h])
    still = np.all(sd <= thr, axis=1) & np.all(jump <= step_tol, axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], still.astype(np.int8), [0]))))
    trim = w // 2
    poses = []
    block = max(1, int(round(BLOCK_S * rate_hz)))
    tol = 4.0 * np.maximum(np.median(sd, axis=0), floor) / math.sqrt(w)
    for s0, s1 in zip(edges[::2], edges[1::2], strict=True):
        a0, a1 = s0 + trim, s1 - trim
        if (a1 - a0) < min_pose_s * rate_hz:
            continue
        # a turn starts slowly (1 - cos): its first part passes the spread test; keep only the samples whose
        # local mean stays within 4 standard errors of the pose's level (median of the central half)
        c0, c1 = a0 + (a1 - a0) // 4, a1 - (a1 - a0) // 4
        level_now = np.median(mm[c0:c1], axis=0)
        near = np.all(np.abs(mm[a0:a1] - level_now) <= tol, axis=1)
        while a0 < a1 and not near[0]:
            near, a0 = near[1:], a0 + 1
        while a1 > a0 and not near[-1]:
            near, a1 = near[:-1], a1 - 1
        a1 = max(a0, a1 - trim)  # the window that saw the turn begin is centred half a window later
        a0 = min(a1, a0 + trim) if a0 > s0 + trim else a0
        if (a1 - a0) < min_pose_s * rate_hz:
            continue
        seg = accel[a0:a1]
        mean = seg.mean(axis=0)
        nb = (a1 - a0) // block
        bm = seg[: nb * block].reshape(nb, block, m).mean(axis=1)
        # spread of the block means from their successive differences: a slow creep does not inflate it
        se = (
            np.sqrt(np.mean(np.diff(bm, axis=0) ** 2, axis=0) / 2.0 / nb)
            if nb >= 3
            else seg.std(axis=0) / math.sqrt(len(seg))
        )
        if steps is not None:
            # the spread of rounded samples includes the rounding itself (q^2/12): take it out to get the
            # analog noise that dithers the read-out
            if noise_sd is not None:
                sd_an = np.full(m, float(noise_sd))
            else:
                sd_an = np.sqrt(np.maximum(seg.var(axis=0) - steps**2 / 12.0, 0.0))
            q = np.array([quantisation_bias(float(sd_an[j]), float(steps[j])) for j in range(m)])
        else:
            q = np.zeros(m)
        half = len(seg) // 2
        d = np.abs(seg[:half].mean(axis=0) - seg[half:].mean(axis=0))
        t0, t1 = a0 / rate_hz, a1 / rate_hz
        bad = (d > 6.0 * 2.0 * se) & (d > DRIFT_MAX_G * G0)  # the rounding error is common to both halves
        if bad.any():
            j = int(np.flatnonzero(bad)[0])
            raise CalibrationError(
                f"pose at {t0:.1f}..{t1:.1f} s is not still: axis {j} moves by {d[j] / G0 * 1e3:.3g} mg between "
                f"its halves (more than {DRIFT_MAX_G * 1e3:g} mg and 6 standard errors); hold each pose steady"
            )
        level = np.round(mean / G0)
        poses.append(Pose(int(a0), int(a1), t0, t1, mean, se, q, level))
    return poses


def check_poses(poses: list[Pose], names: tuple[str, ...]) -> None:
    """Refuse misaligned poses, too few poses, or an axis never read at two levels (one line each)."""
    for k, p in enumerate(poses):
        g = p.mean / G0
        reading = ", ".join(f"{n} {v:+.3f}" for n, v in zip(names, g, strict=True))
        off = np.abs(g - p.level)
        if np.any(np.abs(p.level) > 1) or np.any(off > ALIGN_TOL_G) or np.sum(np.abs(p.level)) > 1:
            raise CalibrationError(
                f"pose {k + 1} at {p.t0:.1f}..{p.t1:.1f} s reads ({reading}) g: not within {ALIGN_TOL_G:g} g of an "
                "aligned pose (one axis at +-1 g, the others at 0 g); calibrate needs aligned poses"
            )
    if len(poses) > MAX_POSES:
        raise CalibrationError(
            f"found {len(poses)} still poses; accepted: at most {MAX_POSES} (cut the recording to the calibration)"
        )
    if len(poses) < MIN_POSES:
        raise CalibrationError(
            f"found {len(poses)} still pose(s), need at least {MIN_POSES} (hold each pose still for "
            f"{MIN_POSE_S:g} s or more; the six-position test gives 6)"
        )
    for j, name in enumerate(names):
        levels = sorted({int(p.level[j]) for p in poses})
        if len(levels) < 2:
            raise CalibrationError(
                f"axis {name}: every pose reads it at {levels[0]:+d} g; offset and sensitivity need it at two of "
                "+1, 0 and -1 g (turn that axis up and down)"
            )


def fit_axes(poses: list[Pose], names: tuple[str, ...], *, cross: bool = True) -> Calibration:
    """Per-axis weighted least squares of offset, scale and (where identifiable) cross terms."""
    check_poses(poses, names)
    L = np.array([p.level for p in poses])  # (poses, axes) in g
    out = []
    for i, name in enumerate(names):
        y = np.array([p.mean[i] for p in poses])
        # covariance of the pose means: noise, independent; rounding error, the same for poses at the same level
        # (their readings fall at the same place between two codes)
        q = np.array([p.quant[i] for p in poses])
        V = np.diag([p.se[i] ** 2 for p in poses]) + np.outer(q, q) / 2.0 * (L[:, i][:, None] == L[:, i][None, :])
        cols = [np.ones(len(poses)), G0 * L[:, i]]
        labels = ["offset", "scale"]
        missing = []
        if cross:
            for k, other in enumerate(names):
                if k == i:
                    continue
                trial = np.column_stack(cols + [G0 * L[:, k]])
                if np.linalg.matrix_rank(trial) == trial.shape[1] and len(poses) > trial.shape[1]:
                    cols.append(G0 * L[:, k])
                    labels.append(other)
                else:
                    missing.append(
                        f"cross-axis to {other} (needs {other} at +-1 g while {name} reads 0, and a spare pose)"
                    )
            if len(names) == 2:
                missing.append("cross-axis to the out-of-plane axis (a 2-axis part cannot tell flat up from flat down)")
        X = np.column_stack(cols)
        Ci = np.linalg.inv(np.linalg.cholesky(V))  # whitening: Ci V Ci^T = I
        A = Ci @ X
        beta, *_ = np.linalg.lstsq(A, Ci @ y, rcond=None)
        cov = np.linalg.inv(A.T @ A)
        r = y - X @ beta
        chi2 = float(np.sum((Ci @ r) ** 2))
        dof = len(poses) - X.shape[1]
        scaled = dof >= 3 and chi2 / dof > 1.0
        q = 1.959964
        if scaled:
            cov = cov * (chi2 / dof)
            q = float(stats.t.ppf(0.975, dof))
        sd = np.sqrt(np.diag(cov))
        est = {lab: float(b) for lab, b in zip(labels, beta, strict=True)}
        out.append(
            AxisCal(
                name=name,
                offset=est["offset"],
                scale=est["scale"],
                cross={lab: est[lab] for lab in labels[2:]},
                se=dict(zip(labels, (float(s) for s in sd), strict=True)),
                ci95={
                    lab: (est[lab] - q * float(s), est[lab] + q * float(s)) for lab, s in zip(labels, sd, strict=True)
                },
                not_identified=tuple(missing),
                chi2=chi2,
                dof=dof,
                residual_rms=float(np.sqrt(np.mean(r**2))),
                scaled=scaled,
            )
        )
    return Calibration(tuple(poses), tuple(out))


def native(model_axis, offset: float, scale: float) -> tuple[float, float]:
    """(zero_g, sensitivity) in the sensor's native units that absorb ``offset`` [m/s^2] and ``scale``.

    The recording was converted as a = (x - zero_g) / sensitivity * G0 from the read-out's x (volts or
    duty); the true relation x = zero' + sensitivity' a / G0 then gives a = offset + scale a_true with
    offset = (zero' - zero_g) / sensitivity * G0 and scale = sensitivity' / sensitivity.
    """
    return model_axis.zero_g + offset * model_axis.sensitivity / G0, model_axis.sensitivity * scale


# --------------------------------------------------------------------------
# Poses in any orientation (3 axes): the gravity-magnitude (ellipsoid) calibration

MIN_POSES_ANY = 6  # offsets and sensitivities of 3 axes: 6 unknowns, one equation (|gravity| = 1 g) per pose
MIN_POSES_ANGLES = 10  # and the 3 angles between the axes, with a spare pose
PLANE_MIN = 0.02  # smallest eigenvalue of the poses' mean (up up^T): below (rms 8 deg out of a plane), near one plane
AXIS_MAX_MIN = 0.5  # some pose must read each axis at least this far from 0 g (in g) ...
AXIS_SPAN_MIN = 0.5  # ... and the readings of each axis must span at least this much (in g)
SCALE_SE_MAX = 0.02  # a sensitivity known to worse than 2 %, or an offset to worse than 20 mg: refused
OFFSET_SE_MAX_G = 0.02


@dataclass(frozen=True)
class PairCal:
    """Angle between two sensing axes (gravity-magnitude method): n_i . n_k, the cosine of their angle."""

    name: str  # "x-y"
    value: float  # n_i . n_k (0 for orthogonal axes; about c_ik + c_ki of the known-orientation model)
    se: float
    ci95: tuple[float, float]


def is_aligned(p: Pose) -> bool:
    """Within ``ALIGN_TOL_G`` of an aligned pose: each axis at +-1 or 0 g, at most one at +-1 g."""
    g = p.mean / G0
    return not (np.any(np.abs(p.level) > 1) or np.any(np.abs(g - p.level) > ALIGN_TOL_G) or np.sum(np.abs(p.level)) > 1)


def calibrate(poses: list[Pose], names: tuple[str, ...], *, cross: bool = True) -> Calibration:
    """Choose the method from the poses: all aligned -> known orientations (:func:`fit_axes`); else, with 3
    axes, the gravity magnitude (:func:`fit_gravity`); else refused (one line, says why and what to do)."""
    if len(poses) > MAX_POSES:
        raise CalibrationError(
            f"found {len(poses)} still poses; accepted: at most {MAX_POSES} (cut the recording to the calibration)"
        )
    tilted = [k for k, p in enumerate(poses) if not is_aligned(p)]
    if not tilted:
        return fit_axes(poses, names, cross=cross)
    if len(names) == 3:
        return fit_gravity(poses, names, cross=cross)
    k = tilted[0]
    p = poses[k]
    reading = ", ".join(f"{n} {v:+.3f}" for n, v in zip(names, p.mean / G0, strict=True))
    raise CalibrationError(
        f"pose {k + 1} at {p.t0:.1f}..{p.t1:.1f} s reads ({reading}) g: not within {ALIGN_TOL_G:g} g of an aligned "
        f"pose, and a {len(names)}-axis part cannot use tilted poses (gravity's out-of-plane component is not "
        "measured, so neither |g| nor the tilt gives the in-plane level); hold it aligned: "
        + ("x up, x down, y up, y down and flat" if len(names) == 2 else "x up, x down and flat")
        + f" (each axis within {ALIGN_TOL_G:g} g of +-1 or 0 g)"
    )


def _unpack(theta: np.ndarray, angles: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(offset [m/s^2], scale, N) from theta = (offset/G0 (3), scale (3)[, p, q, r]); rows of N are the unit
    sensing directions: x = (1, 0, 0), y = (p, sqrt(1 - p^2), 0), z = (q, r, sqrt(1 - q^2 - r^2))."""
    o = theta[:3] * G0
    s = theta[3:6]
    N = np.eye(3)
    if angles:
        p, q, r = theta[6:9]
        N = np.array(
            [
                [1.0, 0.0, 0.0],
                [p, math.sqrt(max(1 - p * p, 1e-12)), 0.0],
                [q, r, math.sqrt(max(1 - q * q - r * r, 1e-12))],
            ]
        )
    return o, s, N


def _gravity_residuals(theta, M, angles):
    """|gravity| - G0 per pose, gravity = N^-1 diag(1/s) (m - o), and d residual / d m (poses, 3)."""
    o, s, N = _unpack(theta, angles)
    A = np.linalg.inv(N) / s[None, :]  # N^-1 diag(1/s)
    a = (M - o) @ A.T
    norm = np.linalg.norm(a, axis=1)
    return norm - G0, (a / norm[:, None]) @ A


def _pair_values(theta: np.ndarray) -> np.ndarray:
    p, q, r = theta[6:9]
    return np.array([p, q, p * q + math.sqrt(max(1 - p * p, 1e-12)) * r])


def _directions(poses: list[Pose]) -> np.ndarray:
    U = np.array([p.mean for p in poses])
    return U / np.linalg.norm(U, axis=1, keepdims=True)


def check_spread(poses: list[Pose], names: tuple[str, ...]) -> None:
    """Refuse, in one line, pose sets whose directions do not determine every offset and sensitivity."""
    n = len(poses)
    if n < MIN_POSES_ANY:
        raise CalibrationError(
            f"found {n} still pose(s), some tilted; in arbitrary orientations the gravity-magnitude calibration "
            f"needs at least {MIN_POSES_ANY} (6 unknowns, offset and sensitivity of 3 axes, and one equation per "
            f"pose: |gravity| = 1 g; {MIN_POSES_ANGLES} with the angles between the axes); add poses, or hold "
            f"{MIN_POSES} or more aligned ones (the six-position test)"
        )
    U = _directions(poses)
    w, V = np.linalg.eigh(U.T @ U / n)
    if w[1] < PLANE_MIN:
        d = V[:, 2] * np.sign(V[np.argmax(np.abs(V[:, 2])), 2])
        spread = math.degrees(math.asin(min(1.0, math.sqrt(max(w[0] + w[1], 0.0)))))
        raise CalibrationError(
            f"all {n} poses lie within about {spread:.0f} deg of one direction (up = "
            + ", ".join(f"{nm} {round(float(v), 2) + 0.0:+.2f}" for nm, v in zip(names, d, strict=True))
            + " and its opposite): the offsets and sensitivities of the other axes are not identifiable; "
            "turn the part so that each axis points up, down and sideways in some poses"
        )
    if w[0] < PLANE_MIN:
        nrm = V[:, 0] * np.sign(V[np.argmax(np.abs(V[:, 0])), 0])
        tilt = math.degrees(math.asin(min(1.0, math.sqrt(max(w[0], 0.0)))))
        raise CalibrationError(
            f"all {n} poses lie near one plane (rms {tilt:.0f} deg out of it; its normal: "
            + ", ".join(f"{nm} {round(float(v), 2) + 0.0:+.2f}" for nm, v in zip(names, nrm, strict=True))
            + "): the sensitivity along the normal is not identifiable; add poses with the normal pointing up "
            "and down"
        )
    for j, name in enumerate(names):
        lo, hi = float(U[:, j].min()), float(U[:, j].max())
        if max(abs(lo), abs(hi)) < AXIS_MAX_MIN:
            raise CalibrationError(
                f"axis {name}: every pose reads it between {lo:+.2f} and {hi:+.2f} g (near the plane of the other "
                f"axes): its offset and sensitivity are not identifiable; add poses with {name} near +1 and -1 g"
            )
        if hi - lo < AXIS_SPAN_MIN:
            raise CalibrationError(
                f"axis {name}: every pose reads it between {lo:+.2f} and {hi:+.2f} g (all poses near one "
                f"direction of it): its offset and sensitivity cannot be told apart; add poses with {name} at "
                "other levels (up, down, sideways)"
            )


def fit_gravity(poses: list[Pose], names: tuple[str, ...], *, cross: bool = True) -> Calibration:
    """Offsets, sensitivities and (with ``cross`` and enough poses) the angles between the axes of a 3-axis
    part from still poses in any orientation: |N^-1 diag(1/s) (m - o)| = G0 in every pose, by weighted
    nonlinear least squares (see the module docstring)."""
    if len(names) != 3:
        raise CalibrationError(f"the gravity-magnitude calibration needs 3 axes; the model has {len(names)}")
    n = len(poses)
    angles = cross and n >= MIN_POSES_ANGLES
    check_spread(poses, names)
    M = np.array([p.mean for p in poses])
    var = np.array([p.se**2 + p.quant**2 / 2.0 for p in poses])  # (poses, 3); independent between poses
    theta = np.concatenate((np.zeros(3), np.ones(3), np.zeros(3 if angles else 0)))
    sig = np.ones(n)
    for _ in range(3):  # the weights depend (weakly) on theta: refit with them re-evaluated
        _, D = _gravity_residuals(theta, M, angles)
        sig = np.sqrt(np.sum(D**2 * var, axis=1))

        def fun(th, sig=sig):
            return _gravity_residuals(th, M, angles)[0] / sig

        res = optimize.least_squares(fun, theta, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12)
        theta = res.x
    J = res.jac
    r, _ = _gravity_residuals(theta, M, angles)
    chi2 = float(np.sum((r / sig) ** 2))
    k = len(theta)
    dof = n - k
    try:
        cov = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((k, k), np.inf)
    scaled = dof >= 3 and chi2 / dof > 1.0
    qn = 1.959964
    if scaled:
        cov = cov * (chi2 / dof)
        qn = float(stats.t.ppf(0.975, dof))
    sd = np.sqrt(np.abs(np.diag(cov)))
    for j, name in enumerate(names):
        if not (sd[3 + j] <= SCALE_SE_MAX and sd[j] <= OFFSET_SE_MAX_G):
            raise CalibrationError(
                f"axis {name}: the {n} poses determine its sensitivity to {sd[3 + j] * 100:.2g} % and its offset to "
                f"{sd[j] * 1e3:.3g} mg (se; accepted: {SCALE_SE_MAX * 100:g} % and {OFFSET_SE_MAX_G * 1e3:g} mg): "
                f"the poses do not spread enough; add poses with {name} up, down and sideways"
            )
    o, s, _ = _unpack(theta, angles)
    missing_all = []
    if cross and not angles:
        missing_all.append(
            f"the angles between the axes (the gravity-magnitude fit needs {MIN_POSES_ANGLES} poses or more for "
            f"them; found {n})"
        )
    axes = []
    for j, name in enumerate(names):
        miss = list(missing_all)
        if cross:
            miss.append(
                f"cross-axis terms of {name} one by one (with unknown orientations only the angles between the axes "
                "are known: see the axis pairs)"
            )
        se_o, se_s = float(sd[j] * G0), float(sd[3 + j])
        axes.append(
            AxisCal(
                name=name,
                offset=float(o[j]),
                scale=float(s[j]),
                cross={},
                se={"offset": se_o, "scale": se_s},
                ci95={
                    "offset": (float(o[j]) - qn * se_o, float(o[j]) + qn * se_o),
                    "scale": (float(s[j]) - qn * se_s, float(s[j]) + qn * se_s),
                },
                not_identified=tuple(miss),
                chi2=chi2,
                dof=dof,
                residual_rms=float(np.sqrt(np.mean(r**2))),
                scaled=scaled,
            )
        )
    pairs = []
    if angles:
        vals = _pair_values(theta)
        G = np.zeros((3, k))
        h = 1e-7
        for c in range(6, 9):
            e = np.zeros(k)
            e[c] = h
            G[:, c] = (_pair_values(theta + e) - _pair_values(theta - e)) / (2 * h)
        pcov = G @ cov @ G.T
        for (a, b), v, var_p in zip(((0, 1), (0, 2), (1, 2)), vals, np.diag(pcov), strict=True):
            se_p = math.sqrt(max(var_p, 0.0))
            pairs.append(PairCal(f"{names[a]}-{names[b]}", float(v), se_p, (v - qn * se_p, v + qn * se_p)))
    return Calibration(tuple(poses), tuple(axes), method=GRAVITY, pairs=tuple(pairs))
