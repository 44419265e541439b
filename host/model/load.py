"""Read and validate an accelnav model file (TOML).

The model file is the single source of truth for a sensor, its sampling, the
bias model of every axis, the noise figures, the declared ranges and the
filter options. :func:`load_model` turns it into one immutable :class:`Model`;
everything derived from it (Ts, phi, b, F, Q, H, code conversion) is computed
in :mod:`codegen.design` and nowhere else.

A bad file raises :class:`ModelError` whose message is one line naming the
file, the key, what was wrong and what is accepted.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import re
import threading
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from accelnav.resources import models_dir

G0 = 9.80665  # standard gravity, m/s^2

# the embedded default, shipped as package data (accelnav.models)
DEFAULT_MODEL = models_dir() / "adxl250_default.toml"

SENSOR_KINDS = ("analog", "duty_cycle", "calibrated")
CALIBRATED_UNITS = ("g", "m/s^2")
FILTER_FORMS = ("covariance", "gain_schedule")

# Physical bounds on the keys that set a loop's length in the generator (the Riccati run, the l1 sums):
# a bias time constant beyond 1e7 s (116 days) is a constant bias over any run accepted here, and a
# dead-reckoning run of 1e6 s (11.6 days) is far past what position from an accelerometer is good for.
MAX_T_S = 1e7
MAX_RUN_S = 1e6

# --------------------------------------------------------------------------
# The one rule for strings that reach generated C (identifiers, comments), a report, a path.

_C_IDENT = (re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}"), "a C identifier of 1 to 32 of A-Z a-z 0-9 _, first a letter")
_NAME_RULES = {
    # model name: printed in C comments, the report, manifests; no '/' or '*' (no comment can open or
    # close), no quote, backslash, '?' (trigraphs), '$', ';', '&', '|', '<', '>', no newline, ASCII only
    "model name": (
        re.compile(r"[A-Za-z0-9][A-Za-z0-9 _.,:+=()-]{0,63}"),
        "1 to 64 of A-Z a-z 0-9 space _ . , : + = ( ) -, starting with a letter or digit",
    ),
    # axis names and the C prefix become parts of C identifiers, macro and file names
    "axis name": _C_IDENT,
    "C prefix": _C_IDENT,
    # free text inside a generated /* ... */ comment (the emitters' banner): printable ASCII on one line
    "comment": (
        re.compile(r"[^\\?\x00-\x1f\x7f-\U0010ffff]{0,200}"),
        "at most 200 printable ASCII but \\ and ? on one line",
    ),
}

# C89..C23 keywords, and the macros of <stdbool.h>/<stddef.h>/<errno.h> the generated C sits beside
C_RESERVED = frozenset(
    """auto break case char const continue default do double else enum extern float for goto if inline int
    long register restrict return short signed sizeof static struct switch typedef union unsigned void
    volatile while alignas alignof bool constexpr false nullptr static_assert thread_local true typeof
    typeof_unqual asm fortran NULL EOF errno assert offsetof""".split()
)


def name_problem(kind: str, value: object) -> str | None:
    """None when ``value`` is safe as a ``kind`` (a key of _NAME_RULES), else what is accepted (one line).

    The loader refuses a model with it, the codegen CLI a --prefix, and the emitters check their
    banner text with it again, so nothing reaches C that could close a comment or leave an identifier."""
    pattern, accepted = _NAME_RULES[kind]
    if not isinstance(value, str) or not pattern.fullmatch(value):
        return accepted
    if "*/" in value or "/*" in value:  # the comment rule's printable ASCII still holds these
        return accepted + ", without */ or /*"
    if kind in ("axis name", "C prefix") and value in C_RESERVED:
        return accepted + ", not a C keyword or standard macro"
    return None


def c_identifier_from(text: str, prefix: str) -> str:
    """``prefix`` + ``text`` made a name that passes the C-identifier rule (``_C_IDENT``: what axis names and the
    C prefix must be), for names that reach C, a Makefile and a file name at once (the Arduino library's).
    Each run of characters outside A-Z a-z 0-9 becomes one _; when that changed ``text`` or the rule's 32
    characters cut it, 6 hex digits of its sha256 follow, so models whose names differ keep apart."""
    body = re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")
    room = 32 - len(prefix)
    if body != text or len(body) > room:
        tag = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:6]
        body = f"{body[: room - 7].rstrip('_')}_{tag}".lstrip("_")
    name = prefix + body
    problem = name_problem("C prefix", name)
    if problem:  # a prefix that is no C identifier itself: the caller's bug, not the user's
        raise ValueError(f"{name!r}: {problem}")
    return name


def model_name_from(text: str) -> str:
    """A model name that passes the rule, made from free text (a recording's file name): every other
    character becomes _, cut to the rule's 64."""
    pattern = _NAME_RULES["model name"][0]
    name = "".join(c if pattern.fullmatch("a" + c) else "_" for c in text)
    if not pattern.fullmatch(name[:1]):
        name = "m" + name
    return name[:64]


class ModelError(ValueError):
    """A model file that cannot be used; ``str()`` is one line for the user."""

    def __init__(self, source: str, key: str, problem: str):
        self.source = source
        self.key = key
        self.problem = problem
        super().__init__(f"{source}: {key}: {problem}")


@dataclass(frozen=True)
class AnalogInput:
    """ADC read-out of an analog output: V = code * adc_ref_v / 2**adc_bits."""

    supply_v: float
    adc_bits: int
    adc_ref_v: float
    sensitivity_v_per_g: float
    zero_g_v: float

    @property
    def ratiometric(self) -> bool:
        return self.adc_ref_v == self.supply_v


@dataclass(frozen=True)
class DutyCycleInput:
    """Timer capture of a duty-cycle output: A[g] = (T1/T2 - zero_g_duty) / duty_per_g."""

    timer_clock_hz: float
    t2_period_s: float
    zero_g_duty: float
    duty_per_g: float

    @property
    def t2_counts(self) -> int:
        """Nominal T2 period in timer counts."""
        return int(round(self.t2_period_s * self.timer_clock_hz))


@dataclass(frozen=True)
class CalibratedInput:
    """Samples that are already acceleration (an IMU's calibrated output, a log in g or m/s^2).

    ``unit`` is the unit of the samples; ``lsb_per_g`` (0: not given) is the
    resolution of a digital sensor's int16 counts, used by the simulator to
    quantise. No read-out constants: the axes carry no sensitivity or zero level.
    """

    unit: str
    lsb_per_g: float


@dataclass(frozen=True)
class Sensor:
    kind: str
    part: str
    range_g: float
    noise_density_g_rthz: float
    bandwidth_hz: float
    analog: AnalogInput | None
    duty_cycle: DutyCycleInput | None
    calibrated: CalibratedInput | None = None


@dataclass(frozen=True)
class Axis:
    """One sensing axis: its calibration and its bias constants (SI units).

    ``sensitivity`` and ``zero_g`` are in the sensor's native units: V/g and V
    for an analog part, duty/g and duty for a duty-cycle part.
    """

    name: str
    c1: float
    c2: float
    T: float
    sensitivity: float
    zero_g: float


@dataclass(frozen=True)
class Noise:
    sigma_n: float
    sigma_eps: float
    R: float


@dataclass(frozen=True)
class Ranges:
    max_velocity_m_s: float
    max_position_m: float
    max_run_s: float


@dataclass(frozen=True)
class FilterOptions:
    form: str
    initial_sigma: tuple[float, float, float, float]


@dataclass(frozen=True)
class Model:
    name: str
    description: str
    source: str
    sha256: str
    sensor: Sensor
    rate_hz: float
    axes: tuple[Axis, ...]
    noise: Noise
    ranges: Ranges
    filter: FilterOptions
    text: str = field(default="", repr=False, compare=False)  # the file's text, for embedding in outputs

    @property
    def Ts(self) -> float:
        """Sample period, s."""
        return 1.0 / self.rate_hz

    @property
    def max_accel_m_s2(self) -> float:
        """Sensor full scale, m/s^2."""
        return self.sensor.range_g * G0

    def axis(self, name_or_index: str | int) -> Axis:
        """The axis named ``name_or_index``, or at that index; ModelError if there is none."""
        if isinstance(name_or_index, (int, np.integer)) and not isinstance(name_or_index, bool):
            if 0 <= name_or_index < len(self.axes):
                return self.axes[name_or_index]
            raise ModelError(self.source, "axes", f"no axis {name_or_index}; the model has {len(self.axes)}")
        for ax in self.axes:
            if ax.name == name_or_index:
                return ax
        names = ", ".join(a.name for a in self.axes)
        raise ModelError(self.source, "axes", f"no axis named {name_or_index!r}; the model has: {names}")


# --------------------------------------------------------------------------
# Validation helpers. Each takes the table, the dotted path of the table (for
# messages) and the key; each refuses with one ModelError naming that key.


class _Table:
    """A TOML table being consumed; unknown keys are refused at the end."""

    def __init__(self, source: str, path: str, data: object):
        self.source = source
        self.path = path
        if not isinstance(data, dict):
            raise ModelError(source, path or "(top level)", f"expected a table, got {_kind(data)}")
        self.data = data
        self.seen: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, problem: str) -> ModelError:
        return ModelError(self.source, self.key(name), problem)

    def raw(self, name: str, default: object = ...) -> object:
        self.seen.add(name)
        if name in self.data:
            return self.data[name]
        if default is ...:
            raise self.fail(name, "missing; this key is required")
        return default

    def table(self, name: str, required: bool = True) -> _Table | None:
        self.seen.add(name)
        if name not in self.data:
            if required:
                raise self.fail(name, "missing table; this table is required")
            return None
        return _Table(self.source, self.key(name), self.data[name])

    def number(
        self,
        name: str,
        default: object = ...,
        *,
        lo: float | None = None,
        hi: float | None = None,
        lo_open: bool = False,
    ) -> float:
        value = self.raw(name, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(name, f"expected a number, got {_kind(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(name, f"expected a finite number, got {value}")
        _check_range(self, name, value, lo, hi, lo_open)
        return value

    def integer(self, name: str, default: object = ..., *, lo: int, hi: int) -> int:
        value = self.raw(name, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(name, f"expected an integer from {lo} to {hi}, got {_kind(value)}")
        if not lo <= value <= hi:
            raise self.fail(name, f"expected an integer from {lo} to {hi}, got {value}")
        return value

    def string(self, name: str, default: object = ..., *, choices: tuple[str, ...] | None = None) -> str:
        value = self.raw(name, default)
        if not isinstance(value, str):
            raise self.fail(name, f"expected a string, got {_kind(value)}")
        if choices is not None and value not in choices:
            accepted = ", ".join(repr(c) for c in choices)
            raise self.fail(name, f"got {value!r}; accepted: {accepted}")
        return value

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.seen)
        if unknown:
            accepted = ", ".join(sorted(self.seen))
            raise self.fail(unknown[0], f"unknown key; accepted here: {accepted}")


def _check_name(t: _Table, key: str, value: str, kind: str) -> None:
    problem = name_problem(kind, value)
    if problem is not None:
        shown = ascii(value) if len(value) <= 80 else ascii(value[:80]) + "..."  # ascii(): one line, no escapes
        raise t.fail(key, f"got {shown}; accepted: {problem}")


def _kind(value: object) -> str:
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, str):
        return f"a string ({value!r})"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, (int, float)):
        return f"the number {value}"
    return type(value).__name__


def _check_range(t: _Table, name: str, value: float, lo, hi, lo_open: bool) -> None:
    bad_lo = lo is not None and (value <= lo if lo_open else value < lo)
    bad_hi = hi is not None and value > hi
    if bad_lo or bad_hi:
        left = "(" if lo_open else "["
        lo_s = "-inf" if lo is None else f"{lo:g}"
        hi_s = "inf" if hi is None else f"{hi:g}"
        raise t.fail(name, f"got {value:g}; accepted: a number in {left}{lo_s}, {hi_s}]")


# --------------------------------------------------------------------------


def load_model(path: str | Path | None = None) -> Model:
    """Read, validate and return the model at ``path`` (the embedded default if None)."""
    path = Path(path) if path is not None else DEFAULT_MODEL
    source = str(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ModelError(source, "(file)", "no such file") from None
    except OSError as exc:
        raise ModelError(source, "(file)", f"cannot read: {exc.strerror}") from None
    return loads_model(raw, source=source)


# models parsed in this process, by (source, sha256 of the text): a Model is immutable, and a fleet's every
# input parsed the same text twice (5 ms of a 1e5-row file's 80 ms of CPU, measured)
_PARSED: dict[tuple[str, str], Model] = {}
_PARSED_MAX = 8
_PARSED_LOCK = threading.Lock()  # a library caller's threads may parse at once (a Dask worker's, a notebook's)


def loads_model(text: str | bytes, source: str = "<model>") -> Model:
    """Validate model text; ``source`` names it in error messages."""
    raw = text.encode() if isinstance(text, str) else text
    key = (source, hashlib.sha256(raw).hexdigest())
    with _PARSED_LOCK:
        model = _PARSED.get(key)
    if model is None:
        model = _loads(raw, source, key[1])  # outside the lock: a bad text raises, nothing kept
        with _PARSED_LOCK:
            _PARSED[key] = model
            while len(_PARSED) > _PARSED_MAX:
                del _PARSED[next(iter(_PARSED))]  # the oldest
    return model


def _loads(raw: bytes, source: str, sha: str) -> Model:
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ModelError(source, "(file)", f"not UTF-8 text (byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ModelError(source, "(syntax)", f"not valid TOML: {exc}") from None
    model = _parse(data, source, sha)
    return dataclasses.replace(model, text=raw.decode("utf-8"))


def _parse(data: dict, source: str, sha: str) -> Model:
    top = _Table(source, "", data)

    meta = top.table("model")
    name = meta.string("name")
    _check_name(meta, "name", name, "model name")
    description = meta.string("description", "")
    meta.done()

    sensor = _parse_sensor(top.table("sensor"))

    sampling = top.table("sampling")
    rate_hz = sampling.number("rate_hz", lo=1.0, hi=100_000.0)
    sampling.done()
    if sensor.duty_cycle is not None and sensor.duty_cycle.t2_period_s > 1.0 / rate_hz * 1.000001:
        raise ModelError(
            source,
            "sensor.duty_cycle.t2_period_s",
            f"the duty-cycle period {sensor.duty_cycle.t2_period_s:g} s is longer than the sample "
            f"period {1.0 / rate_hz:g} s; accepted: at most 1/sampling.rate_hz",
        )
    axes = _parse_axes(top, sensor, source)

    noise_t = top.table("noise")
    noise = Noise(
        sigma_n=noise_t.number("sigma_n", lo=0.0, lo_open=True),
        sigma_eps=noise_t.number("sigma_eps", lo=0.0),
        R=noise_t.number("R", lo=0.0, lo_open=True),
    )
    noise_t.done()

    rng = top.table("ranges")
    ranges = Ranges(
        max_velocity_m_s=rng.number("max_velocity_m_s", lo=0.0, lo_open=True),
        max_position_m=rng.number("max_position_m", lo=0.0, lo_open=True),
        max_run_s=rng.number("max_run_s", lo=0.0, lo_open=True, hi=MAX_RUN_S),
    )
    rng.done()

    filt = top.table("filter")
    form = filt.string("form", "covariance", choices=FILTER_FORMS)
    sig = filt.raw("initial_sigma", [0.0, 0.0, 1.0, 0.1])
    if (
        not isinstance(sig, list)
        or len(sig) != 4
        or not all(isinstance(s, (int, float)) and not isinstance(s, bool) for s in sig)
    ):
        raise filt.fail("initial_sigma", f"expected an array of 4 numbers [r, u, a, eps], got {_kind(sig)}")
    if not all(math.isfinite(s) and s >= 0 for s in sig):
        raise filt.fail("initial_sigma", f"expected 4 finite numbers >= 0, got {sig}")
    filt.done()

    top.done()
    return Model(
        name=name,
        description=description,
        source=source,
        sha256=sha,
        sensor=sensor,
        rate_hz=rate_hz,
        axes=axes,
        noise=noise,
        ranges=ranges,
        filter=FilterOptions(form=form, initial_sigma=tuple(float(s) for s in sig)),
    )


def _parse_sensor(t: _Table) -> Sensor:
    kind = t.string("kind", choices=SENSOR_KINDS)
    part = t.string("part", "")
    range_g = t.number("range_g", lo=0.0, lo_open=True, hi=1000.0)
    density = t.number("noise_density_g_rthz", lo=0.0)
    bandwidth = t.number("bandwidth_hz", lo=0.0, lo_open=True)
    analog = duty = calibrated = None
    if kind == "calibrated":
        c = t.table("calibrated")
        calibrated = CalibratedInput(
            unit=c.string("unit", choices=CALIBRATED_UNITS),
            lsb_per_g=c.number("lsb_per_g", 0.0, lo=0.0),
        )
        c.done()
        for other in ("analog", "duty_cycle"):
            if other in t.data:
                raise t.fail(other, f"given, but sensor.kind is 'calibrated'; remove it or set kind = {other!r}")
    elif kind == "analog":
        a = t.table("analog")
        supply = a.number("supply_v", lo=0.0, lo_open=True, hi=50.0)
        analog = AnalogInput(
            supply_v=supply,
            adc_bits=a.integer("adc_bits", lo=6, hi=24),
            adc_ref_v=a.number("adc_ref_v", supply, lo=0.0, lo_open=True, hi=50.0),
            sensitivity_v_per_g=a.number("sensitivity_v_per_g", lo=0.0, lo_open=True),
            zero_g_v=a.number("zero_g_v", supply / 2, lo=0.0),
        )
        a.done()
        if analog.zero_g_v >= analog.adc_ref_v:
            raise a.fail("zero_g_v", f"got {analog.zero_g_v:g} V, at or above the ADC reference {analog.adc_ref_v:g} V")
        if "duty_cycle" in t.data:
            raise t.fail("duty_cycle", "given, but sensor.kind is 'analog'; remove it or set kind = 'duty_cycle'")
    else:
        d = t.table("duty_cycle")
        duty = DutyCycleInput(
            timer_clock_hz=d.number("timer_clock_hz", lo=1e3, hi=1e9),
            t2_period_s=d.number("t2_period_s", lo=0.0, lo_open=True, hi=1.0),
            zero_g_duty=d.number("zero_g_duty", 0.5, lo=0.0, lo_open=True, hi=1.0),
            duty_per_g=d.number("duty_per_g", lo=0.0, lo_open=True, hi=1.0),
        )
        d.done()
        if duty.t2_counts < 16:
            raise d.fail(
                "t2_period_s",
                f"gives only {duty.t2_counts} timer counts per period at "
                f"{duty.timer_clock_hz:g} Hz; accepted: at least 16 counts",
            )
        if "analog" in t.data:
            raise t.fail("analog", "given, but sensor.kind is 'duty_cycle'; remove it or set kind = 'analog'")
    if kind != "calibrated" and "calibrated" in t.data:
        raise t.fail("calibrated", f"given, but sensor.kind is {kind!r}; remove it or set kind = 'calibrated'")
    t.done()
    return Sensor(kind, part, range_g, density, bandwidth, analog, duty, calibrated)


def _parse_axes(top: _Table, sensor: Sensor, source: str) -> tuple[Axis, ...]:
    raw = top.raw("axes")
    if not isinstance(raw, list) or not raw:
        raise ModelError(source, "axes", f"expected one or more [[axes]] tables, got {_kind(raw)}")
    if len(raw) > 3:
        raise ModelError(source, "axes", f"got {len(raw)} axes; accepted: 1 to 3")
    if sensor.kind == "calibrated":
        sens_key = zero_key = None
        sens_default, zero_default = 1.0, 0.0
    elif sensor.kind == "analog":
        sens_key, zero_key = "sensitivity_v_per_g", "zero_g_v"
        sens_default, zero_default = sensor.analog.sensitivity_v_per_g, sensor.analog.zero_g_v
    else:
        sens_key, zero_key = "duty_per_g", "zero_g_duty"
        sens_default, zero_default = sensor.duty_cycle.duty_per_g, sensor.duty_cycle.zero_g_duty
    axes = []
    for i, item in enumerate(raw):
        t = _Table(source, f"axes[{i}]", item)
        name = t.string("name")
        _check_name(t, "name", name, "axis name")
        axes.append(
            Axis(
                name=name,
                c1=t.number("c1"),
                c2=t.number("c2"),
                T=t.number("T", lo=0.0, lo_open=True, hi=MAX_T_S),
                sensitivity=t.number(sens_key, sens_default, lo=0.0, lo_open=True) if sens_key else sens_default,
                zero_g=t.number(zero_key, zero_default, lo=0.0) if zero_key else zero_default,
            )
        )
        t.done()
        ax = axes[-1]
        if abs(ax.c1) + abs(ax.c2) > sensor.range_g * G0:
            raise t.fail("c1", "|c1| + |c2| exceeds the sensor's full scale")
        if sensor.kind == "calibrated":
            continue  # no read-out span to fit
        # the sensor's full scale must fit the read-out's input span, or
        # accelerations inside the declared range would be clipped unseen
        lo, hi = ax.zero_g - sensor.range_g * ax.sensitivity, ax.zero_g + sensor.range_g * ax.sensitivity
        span = (0.0, min(sensor.analog.supply_v, sensor.analog.adc_ref_v)) if sensor.analog else (0.0, 1.0)
        if lo < span[0] or hi > span[1]:
            unit = "V" if sensor.analog else "(duty)"
            raise t.fail(
                sens_key,
                f"+-{sensor.range_g:g} g spans {lo:.4g}..{hi:.4g} {unit}, outside the read-out's "
                f"{span[0]:g}..{span[1]:g}; accepted: zero_g +- range_g * sensitivity inside it",
            )
    names = [a.name for a in axes]
    if len(set(names)) != len(names):
        raise ModelError(source, "axes", f"axis names must differ, got {names}")
    # the C upper-cases names into macros (x and X collide) and appends suffixes to them
    # (accelnav_x_out_t is axis x's output type and axis x_out's state type)
    folded = [n.casefold() for n in names]
    for i, a in enumerate(folded):
        for j, b in enumerate(folded):
            if i != j and (a == b or b.startswith(a + "_")):
                raise ModelError(
                    source,
                    f"axes[{j}].name",
                    f"{names[j]!r} collides with axis {names[i]!r} in the generated C; accepted: names that "
                    "differ ignoring case, none another's name followed by _",
                )
    return tuple(axes)
