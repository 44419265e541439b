"""Design numbers derived from a model: the one place they are computed.

For one axis with period Ts and state x = [r, u, a, eps] (position, velocity,
acceleration, bias):

    x[k+1] = F x[k] + b + w[k],   w ~ N(0, Q)
    z[k]   = H x[k] + v[k],       v ~ N(0, R)

    F = [[1, Ts, Ts^2/2, 0], [0, 1, Ts, 0], [0, 0, 1, 0], [0, 0, 0, phi]]
    phi = T / (T + Ts),   b = [0, 0, 0, Ts (c1 + c2) / (T + Ts)]
    H = [0, 0, 1, 1]
    Q = sigma_n^2 [[Ts^5/20, Ts^4/8, Ts^3/6, 0], [Ts^4/8, Ts^3/3, Ts^2/2, 0],
                   [Ts^3/6, Ts^2/2, Ts, 0], [0, 0, 0, 0]],  Q[3,3] = Ts sigma_eps^2

The bias recursion eps[k+1] = phi eps[k] + b[3] is the backward-Euler
discretisation of T d(eps)/dt = (c1 + c2) - eps, whose solution from eps(0) = c2
is the paper's eps(t) = c1 (1 - exp(-t/T)) + c2; its fixed point is c1 + c2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .load import G0, Axis, Model

STATE_NAMES = ("r", "u", "a", "eps")
STATE_UNITS = ("m", "m/s", "m/s^2", "m/s^2")


def _frozen(a) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class AxisDesign:
    """Everything the filter of one axis needs, in float64 and SI units."""

    axis: Axis
    Ts: float
    phi: float
    b: np.ndarray  # (4,)
    F: np.ndarray  # (4, 4)
    Q: np.ndarray  # (4, 4)
    H: np.ndarray  # (1, 4)
    R: float
    x0: np.ndarray  # (4,) prior mean of the state at sample 0
    P0: np.ndarray  # (4, 4) prior covariance at sample 0

    @property
    def eps_mean(self) -> float:
        """Steady-state bias c1 + c2 (the fixed point of the bias recursion)."""
        return self.axis.c1 + self.axis.c2


def transition(Ts: float, T: float) -> tuple[np.ndarray, float]:
    """F and phi for period Ts and bias time constant T."""
    phi = T / (T + Ts)
    F = np.array(
        [
            [1.0, Ts, Ts * Ts / 2.0, 0.0],
            [0.0, 1.0, Ts, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, phi],
        ]
    )
    return F, phi


def process_noise(Ts: float, sigma_n: float, sigma_eps: float) -> np.ndarray:
    """Q of DESIGN.md: white jerk of intensity sigma_n^2, bias random walk sigma_eps^2."""
    Q = sigma_n**2 * np.array(
        [
            [Ts**5 / 20, Ts**4 / 8, Ts**3 / 6, 0.0],
            [Ts**4 / 8, Ts**3 / 3, Ts**2 / 2, 0.0],
            [Ts**3 / 6, Ts**2 / 2, Ts, 0.0],
            [0.0, 0.0, 0.0, 0.0],
        ]
    )
    Q[3, 3] = Ts * sigma_eps**2
    return Q


def axis_design(model: Model, axis: str | int = 0) -> AxisDesign:
    """The float64 design numbers of one axis of ``model``."""
    ax = model.axis(axis)
    Ts = model.Ts
    F, phi = transition(Ts, ax.T)
    b = np.array([0.0, 0.0, 0.0, Ts * (ax.c1 + ax.c2) / (ax.T + Ts)])
    Q = process_noise(Ts, model.noise.sigma_n, model.noise.sigma_eps)
    H = np.array([[0.0, 0.0, 1.0, 1.0]])
    x0 = np.array([0.0, 0.0, 0.0, ax.c2])
    P0 = np.diag(np.square(model.filter.initial_sigma))
    return AxisDesign(
        axis=ax,
        Ts=Ts,
        phi=phi,
        b=_frozen(b),
        F=_frozen(F),
        Q=_frozen(Q),
        H=_frozen(H),
        R=model.noise.R,
        x0=_frozen(x0),
        P0=_frozen(P0),
    )


# --------------------------------------------------------------------------
# Raw input -> acceleration. The simulator produces the raw values; the
# reference filter and the generated C both start from them.


@dataclass(frozen=True)
class AnalogConversion:
    """a [m/s^2] = code * scale + offset; codes 0 and full_code are rails."""

    scale: float
    offset: float
    full_code: int

    def accel(self, code) -> np.ndarray:
        return np.asarray(code, dtype=np.float64) * self.scale + self.offset

    def clipped(self, code) -> np.ndarray:
        code = np.asarray(code)
        return (code <= 0) | (code >= self.full_code)


@dataclass(frozen=True)
class DutyConversion:
    """a [m/s^2] = (T1/T2 - zero_g_duty) / duty_per_g * g0.

    A capture is invalid (skip the update) when T2 is zero, when T2 is off the
    nominal period by more than 25 %, or when T1 is 0 or >= T2 (output stuck).
    """

    zero_g_duty: float
    duty_per_g: float
    t2_nominal: int

    def accel(self, t1, t2) -> np.ndarray:
        t1 = np.asarray(t1, dtype=np.float64)
        t2 = np.asarray(t2, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            duty = np.where(t2 > 0, t1 / np.where(t2 > 0, t2, 1.0), self.zero_g_duty)
        return (duty - self.zero_g_duty) / self.duty_per_g * G0

    def clipped(self, t1, t2) -> np.ndarray:
        t1 = np.asarray(t1)
        t2 = np.asarray(t2)
        off_period = np.abs(t2.astype(np.int64) * 4 - 4 * self.t2_nominal) > self.t2_nominal
        return (t2 <= 0) | off_period | (t1 <= 0) | (t1 >= t2)


@dataclass(frozen=True)
class CalibratedConversion:
    """a [m/s^2] = value * scale: the raw sample is already an acceleration in the model's unit.

    A sample is clipped when it is not finite or at (or beyond) the declared
    full scale, where a digital sensor saturates.
    """

    scale: float
    full_scale: float  # m/s^2

    def accel(self, value) -> np.ndarray:
        return np.asarray(value, dtype=np.float64) * self.scale

    def clipped(self, value) -> np.ndarray:
        a = np.asarray(value, dtype=np.float64) * self.scale
        with np.errstate(invalid="ignore"):
            return ~np.isfinite(a) | (np.abs(a) >= self.full_scale * (1 - 1e-9))


def input_conversion(model: Model, axis: str | int = 0) -> AnalogConversion | DutyConversion | CalibratedConversion:
    """How raw samples of ``axis`` become acceleration."""
    ax = model.axis(axis)
    if model.sensor.kind == "calibrated":
        return CalibratedConversion(scale=G0 if model.sensor.calibrated.unit == "g" else 1.0,
                                    full_scale=model.max_accel_m_s2)  # fmt: skip
    if model.sensor.kind == "analog":
        an = model.sensor.analog
        volts_per_code = an.adc_ref_v / 2**an.adc_bits
        scale = volts_per_code / ax.sensitivity * G0
        return AnalogConversion(scale=scale, offset=-ax.zero_g / ax.sensitivity * G0, full_code=2**an.adc_bits - 1)
    dc = model.sensor.duty_cycle
    return DutyConversion(zero_g_duty=ax.zero_g, duty_per_g=ax.sensitivity, t2_nominal=dc.t2_counts)


def steps_and_noise(model: Model) -> tuple[np.ndarray, float]:
    """Read-out step per model axis [m/s^2] (0 for samples that come calibrated without a stated resolution) and
    the analog noise sd in front of it [m/s^2]: the datasheet's density over the output filter's equivalent
    noise bandwidth (one pole: pi/2 x -3 dB)."""
    s = model.sensor
    steps = []
    for i in range(len(model.axes)):
        if s.kind == "analog":
            steps.append(input_conversion(model, i).scale)
        elif s.kind == "duty_cycle":
            steps.append(G0 / (s.duty_cycle.t2_counts * model.axes[i].sensitivity))
        else:
            lsb = s.calibrated.lsb_per_g if s.calibrated is not None else 0.0
            steps.append(G0 / lsb if lsb > 0 else 0.0)
    noise = s.noise_density_g_rthz * G0 * math.sqrt(math.pi / 2.0 * s.bandwidth_hz)
    return np.array(steps), noise
