"""Column rules: which column is time, which are acceleration axes, and their units, read from the names.

One place for every reader (CSV, gzip CSV, columns in memory, the streamed CSV) and so for every command.
A name says its unit by a suffix (``acc_x_g``, ``ax_m_s2``, ``x_counts``) or in brackets, as phone apps
write it (phyphox ``Linear Acceleration x (m/s^2)``, ``Time (s)``; ``time[ms]``). An acceleration column
is ``acc``/``accel``/``acceleration`` and an axis (``acc_x``, ``accX``, ``Acceleration x``), ``a`` and an
axis letter (``ax``, ``a_y``), a bare axis letter (``x``, as Sensor Logger writes ``z,y,x``), a model axis's
own name (``A0``), or what accelnav itself writes: ``x_accel`` (m/s^2: ``sim --csv``, the smoother's CSV)
and ``x_code`` (raw counts: ``log export``). A time column is ``t``, ``time``, ``timestamp`` or
``seconds_elapsed``, with its unit said the same ways (``t_ms``, ``timestamp_ns``, ``Time (s)``).
"""

from __future__ import annotations

import re

from accelnav.errors import UserError
from accelnav.fileio import excerpt
from accelnav.model.load import G0

# "counts": raw read-out codes (ADC, digital LSB), kept as they are here; the model's own conversion turns
# them into acceleration (accelnav.data.recording.in_accel), so the scale is 1
UNITS = {"g": G0, "mg": G0 * 1e-3, "m/s^2": 1.0, "counts": 1.0}
UNIT_ALIASES = {
    "counts": "counts",
    "count": "counts",
    "lsb": "counts",
    "g": "g",
    "mg": "mg",
    "m/s^2": "m/s^2",
    "m/s2": "m/s^2",
    "m/s²": "m/s^2",
    "mps2": "m/s^2",
    "m_s2": "m/s^2",
    "ms2": "m/s^2",
}
_UNIT_WORDS = r"g|mg|m_s2|mps2|ms2|m/s\^?2|m/s²|counts|count|lsb"
_UNIT_SUFFIX = re.compile(rf"(?:_|\s*\[\s*|\s*\(\s*)({_UNIT_WORDS})\s*[\])]?$", re.IGNORECASE)

MIN_CLOCK_HZ = 5.0  # a time column in seconds slower than this is no accelerometer's: a ms clock, say
EPOCH_S = (946684800.0, 4102444800.0)  # 2000-01-01 .. 2100-01-01 UTC: a clock there is a calendar's, not uptime
MAX_CLOCK_HZ = 1e5  # no accelerometer this package reads samples faster
TIME_SCALE = {None: 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
TIME_UNITS = ("s", "ms", "us", "ns")
_TIME_UNIT_WORDS = {"s": "s", "sec": "s", "ms": "ms", "us": "us", "µs": "us", "μs": "us", "ns": "ns"}
_TIME_NAME = re.compile(
    r"^(t|time|timestamp|seconds_elapsed)(?:_(s|ms|us|ns)|\s*[\[(]\s*(s|sec|ms|us|µs|μs|ns)\s*[\])])?$", re.IGNORECASE
)

# "acc", "accel" or "acceleration" (after "linear", phyphox) and what follows: the axis
_ACC_WORD = re.compile(r"^(?:linear[ _-]?)?(acceleration|accel|acc)(?P<sep>[ _-]?)(?P<rest>.*?)(?:[ _-]?axis)?$", re.I)
_LETTER_FORMS = (
    re.compile(r"^a[ _-]?(?P<axis>[xyz])$", re.IGNORECASE),  # ax, a_y, as logger apps write it
    re.compile(r"^(?P<axis>[xyz])(?:[ _-]?axis)?$", re.IGNORECASE),  # x (Sensor Logger), x-axis
)
_OWN_FORMS = (  # what accelnav writes: (form, the unit its name implies)
    (re.compile(r"^(?P<axis>[A-Za-z_][A-Za-z0-9_]*)_accel$"), "m/s^2"),  # sim --csv, the smoother's CSV
    (re.compile(r"^(?P<axis>[A-Za-z_][A-Za-z0-9_]*)_code$"), "counts"),  # log export
)


def parse_unit(unit: str) -> str:
    key = unit.strip().lower()
    if key not in UNIT_ALIASES:
        raise UserError(f"unit {excerpt(unit)} is not known; accepted: g, mg, m/s^2, counts")
    return UNIT_ALIASES[key]


def unit_of(col: str) -> str | None:
    """The unit a column's name says (``acc_x_g``: g; ``Acceleration x (m/s^2)``: m/s^2), else None."""
    m = _UNIT_SUFFIX.search(col)
    if m:
        return parse_unit(m.group(1))
    for form, unit in _OWN_FORMS:
        if form.match(col):
            return unit
    return None


def axis_of(col: str, model_axes: list[str] | None = None) -> str | None:
    """The axis an acceleration column holds (``acc_x_g``, ``ax``, ``x``: x), else None (not acceleration).

    A name that is a model axis's (in any case) is that axis, spelled as the model spells it."""
    bare = _UNIT_SUFFIX.sub("", col).strip()
    by_model = {a.lower(): a for a in model_axes or ()}
    if bare.lower() in by_model:
        return by_model[bare.lower()]
    for form, _ in _OWN_FORMS:
        m = form.match(bare)
        if m:
            return _spelled(m.group("axis"), by_model)
    m = _ACC_WORD.match(bare)
    # after a separator any name (acc_east); joined, only an axis letter or digits (accX, acc0: not "accuracy")
    if (
        m
        and re.fullmatch(r"[A-Za-z0-9_]+", m.group("rest"))
        and (m.group("sep") or re.fullmatch(r"[xyzXYZ]|\d+", m.group("rest")))
    ):
        return _spelled(m.group("rest"), by_model)
    for form in _LETTER_FORMS:
        m = form.match(bare)
        if m:
            return _spelled(m.group("axis"), by_model)
    return None


def _spelled(axis: str, by_model: dict[str, str]) -> str:
    """An axis as the model spells it, else a letter in lower case (AX_g and ax_g are both x)."""
    return by_model.get(axis.lower(), axis.lower() if len(axis) == 1 else axis)


def is_time(col: str) -> bool:
    return bool(_TIME_NAME.match(col))


def time_unit_of(col: str | None) -> str | None:
    """The unit a time column's name says (``t_ms``: ms; ``Time (s)``: s; ``seconds_elapsed``: s), else None."""
    m = _TIME_NAME.match(col or "")
    if not m:
        return None
    said = m.group(2) or m.group(3)
    if said:
        return _TIME_UNIT_WORDS[said.lower()]
    return "s" if m.group(1).lower() == "seconds_elapsed" else None


def pick_time(cols: list[str]) -> str | None:
    """The time column among ``cols``: one whose name says its unit first (Sensor Logger writes an unsaid
    epoch ``time`` beside ``seconds_elapsed``), else the first time name."""
    times = [c for c in cols if is_time(c)]
    said = [c for c in times if time_unit_of(c) is not None]
    return (said or times or [None])[0]


# --- IMU columns: gyroscope, orientation quaternion, gravity (accelnav.data.imu) -----------------------------------
# A rate says its unit as an acceleration does, by a suffix or in brackets (gx_rad_s, gyro_x_dps, "Gyroscope x
# (rad/s)", wx[deg/s]); the unit words below. A quaternion's parts are named by letter (qw, quat_x, "q x"):
# numbered parts (q0..q3) do not say which one is w and are refused by the IMU reader.
RATE_UNITS = {"rad/s": 1.0, "deg/s": 3.141592653589793 / 180.0}
_RATE_ALIASES = {"rad/s": "rad/s", "rad_s": "rad/s", "rads": "rad/s", "rps": "rad/s",
                 "deg/s": "deg/s", "deg_s": "deg/s", "dps": "deg/s", "°/s": "deg/s"}  # fmt: skip
_RATE_SUFFIX = re.compile(r"(?:_|\s*\[\s*|\s*\(\s*)(rad/s|rad_s|rads|rps|deg/s|deg_s|dps|°/s)\s*[\])]?$", re.IGNORECASE)
_GYRO_NAME = re.compile(
    r"^(?:gyro(?:scope)?|gyr|rot(?:ation)?[ _-]?rate|angular[ _-]?(?:rate|velocity)|omega|w|g)[ _-]?(?P<axis>[xyz])$",
    re.IGNORECASE,
)
_QUAT_NAME = re.compile(r"^(?:q|quat(?:ernion)?|orientation[ _-]?q)[ _-]?(?P<part>[wxyz0-3])$", re.IGNORECASE)
_GRAVITY_NAME = re.compile(r"^(?:gravity|grav)[ _-]?(?P<axis>[xyz])$", re.IGNORECASE)
_LINEAR = re.compile(r"^(?:linear|lin|user)[ _-]?acc", re.IGNORECASE)


def _bare(col: str) -> str:
    """A name without its unit (an acceleration's or a rate's), for the IMU rules."""
    return _RATE_SUFFIX.sub("", _UNIT_SUFFIX.sub("", col)).strip()


def rate_unit_of(col: str) -> str | None:
    """The unit a rate column's name says (``gx_dps``: deg/s; ``Gyroscope x (rad/s)``: rad/s), else None."""
    m = _RATE_SUFFIX.search(col)
    return _RATE_ALIASES[m.group(1).lower()] if m else None


def gyro_axis_of(col: str) -> str | None:
    """The axis a gyroscope column holds (``gx``, ``gyro_y_dps``, ``wz``, ``Gyroscope x (rad/s)``), else None."""
    m = _GYRO_NAME.match(_bare(col))
    return m.group("axis").lower() if m else None


def quat_part_of(col: str) -> str | None:
    """The part a quaternion column holds (``qw``: w, ``quat_x``: x; ``q0``: 0, which the reader refuses), else None."""
    m = _QUAT_NAME.match(_bare(col))
    return m.group("part").lower() if m else None


def gravity_axis_of(col: str) -> str | None:
    """The axis of a gravity-vector column (``grav_x``, ``gravity_y_m_s2``, ``Gravity z (m/s^2)``), else None."""
    m = _GRAVITY_NAME.match(_bare(col))
    return m.group("axis").lower() if m else None


def is_linear(col: str) -> bool:
    """An acceleration column named as gravity removed (phyphox ``Linear Acceleration x``, ``lin_acc_x``,
    ``user_acc_x``): an app's linear acceleration, in the device's frame."""
    return bool(_LINEAR.match(col.strip()))


def linear_axis_of(col: str) -> str | None:
    """The axis of a linear-acceleration column (gravity removed: :func:`is_linear`), else None."""
    if not is_linear(col):
        return None
    return axis_of(re.sub(r"^(?:linear|lin|user)[ _-]?", "", col.strip(), flags=re.IGNORECASE))


def epoch_unit(src: str, col: str, t0: float, step: float) -> tuple[str | None, str | None]:
    """(unit, a note saying it) of a time column whose name and flags say no unit, when its numbers are a
    calendar's (Unix time in s, ms, us or ns: the first stamp between 2000 and 2100) and that unit gives a
    rate an accelerometer has; (None, None) when the numbers cannot tell (relative times: uptime, elapsed)."""
    import datetime

    for unit in TIME_UNITS:
        scale = TIME_SCALE[unit]
        if EPOCH_S[0] <= t0 * scale <= EPOCH_S[1] and MIN_CLOCK_HZ <= 1.0 / (step * scale) <= MAX_CLOCK_HZ:
            when = datetime.datetime.fromtimestamp(t0 * scale, datetime.UTC).strftime("%Y-%m-%d %H:%M:%S")
            words = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}[unit]
            return unit, (
                f"{src}: time column {col!r} read as Unix time in {words} (first stamp {when} UTC, "
                f"{1.0 / (step * scale):.6g} Hz); give --time-unit if it is not"
            )
    return None, None
