"""Static multi-position calibration: zero-g offset, sensitivity and cross-axis terms from still poses.

Model (per sensing axis i, accelerations in m/s^2 as converted with the model's current calibration):

    m_i = o_i + s_i g_i + sum_{k != i} c_ik g_k + noise

where g is gravity's projection on the part's axes in the pose (axis i reads +1 g pointing up), o_i the
zero-g offset (everything constant the conversion gets wrong, bias at that moment included), s_i the
sensitivity relative to the model's, c_ik the cross-axis sensitivity to axis k.

Poses
-----
Found automatically: a sample is still when, on every axis, the standard deviation over a ``window_s`` window
is at most ``STILL_K`` times that axis's typical (median) window deviation; runs of still samples lasting
``min_pose_s`` or longer (less half a window at each end) are poses. A pose's mean is its reading; its
standard error comes from the spread of 0.5 s block means, taken from their successive differences (which
allows for short-range correlation of the noise and is not inflated by a creep) plus an allowance for the
read-out's quantisation: with analog noise of sd sigma (the model's: density and bandwidth) on a step q, the
mean of rounded samples is off by at most (q/pi) exp(-2 pi^2 sigma^2 / q^2) (the first harmonic of the
rounding error; the default ADXL250's 12-bit ADC gives up to 0.07 step = 2.2 mg), counted as a sinusoid of
that amplitude at a random phase (variance b^2/2). A turn starts slowly (1 - cos), so a pose is also
trimmed to the samples whose 0.5 s mean stays within 4 standard errors of the pose's central level. A pose
whose two halves differ by more than 2 mg and 6 standard errors is refused as not still.

The poses must be aligned: every axis within ``ALIGN_TOL_G`` of +1, 0 or -1 g, at most one axis at +-1 g
(the six-position test on a cube; with a 2-axis part, +-x, +-y and flat). Tilted poses are refused:
with a 2-axis part gravity's third component, and so the tilt, is not observable.

What is identifiable
--------------------
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
from scipy import stats

from accelnav.codegen.model import G0

WINDOW_S = 0.5
MIN_POSE_S = 3.0
STILL_K = 3.0
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

    @property
    def se_total(self) -> np.ndarray:
        return np.sqrt(self.se**2 + self.quant**2 / 2.0)


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


@dataclass(frozen=True)
class Calibration:
    poses: tuple[Pose, ...]
    axes: tuple[AxisCal, ...]


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
    still = np.all(sd <= thr, axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], still.astype(np.int8), [0]))))
    trim = w // 2
    poses = []
    block = max(1, int(round(BLOCK_S * rate_hz)))
    mm = np.column_stack([_moving_mean(accel[:, j], w) for j in range(m)])
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
