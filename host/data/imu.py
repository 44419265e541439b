"""Phone and IMU logs in, as :class:`accelnav.level.ImuRecord`: body-frame specific force (gravity included,
m/s^2), gyroscope (rad/s) and the device's own orientation where the log has them, on the accelerometer's clock.

:func:`read_imu` reads a file, a folder or a zip; :func:`imu_from_frame` a DataFrame or a mapping of arrays
(the generic column rules). :func:`sniff` tells whether a path is such a log (the recording readers level it
then: :func:`level_recording`). Every file is read whole, its text capped at a quarter of the input limit
(:func:`accelnav.fileio.input_limit`); a zip's members are read in memory, never extracted.

Formats and their conventions (device axes as Android defines them: x right, y up the screen, z out of it):

* **Sensor Logger** (Kelvin Choi's app, Android and iOS): the zip export or its folder, one CSV per sensor,
  each ``time`` (Unix ns) and ``seconds_elapsed`` then its values by name (``z, y, x``). ``TotalAcceleration.csv``
  holds the accelerometer with gravity (Android only); ``Accelerometer.csv`` has gravity removed and
  ``Gravity.csv`` the gravity vector, their sum being the accelerometer. On iOS (``Metadata.csv``'s
  ``platform``) the app keeps CoreMotion's sign (an inertial force: flat face up, gravity reads -z) unless
  "Standardise Units & Frames" was on: the orientation decides where there is one, else the app's default
  (off) is taken and said. ``Gyroscope.csv`` in rad/s; ``Orientation.csv``'s ``qw, qx, qy, qz`` rotate the
  device's axes into a world frame with z up (Android: the rotation vector, device -> east-north-up; iOS:
  CoreMotion's attitude, device -> x-north-z-vertical).
* **phyphox**: a CSV per sensor (or their zip), ``Time (s)`` from the experiment's start, ``Acceleration x
  (m/s^2)`` (the accelerometer with g), ``Linear Acceleration x (m/s^2)`` (without g: refused alone),
  ``Gyroscope x (rad/s)``; phyphox writes Android's sign on both platforms. No orientation.
* **Physics Toolbox Sensor Suite**: one CSV, ``time`` (seconds, or a clock ``HH:MM:SS:mmm``), ``gFx, gFy, gFz``
  (the g-force: the accelerometer with gravity, in g, Android's sign), ``wx, wy, wz`` (rad/s); its ``ax..``
  (gravity removed) are not used, nor its ``Azimuth, Pitch, Roll`` (degrees whose rotation order the
  export does not state: read without them, said in a note).
* **SensorLog** (iOS): one CSV, every sensor with its own clock (``accelerometerTimestamp_sinceReboot(s)``,
  ...), ``accelerometerAccelerationX(G)`` in g with CoreMotion's sign (negated here), ``gyroRotationX(rad/s)``,
  ``motionQuaternionW(R)``.. (CoreMotion's attitude, device -> reference frame with z vertical).
* **A generic IMU CSV** (and :func:`imu_from_frame`): the column rules of :mod:`accelnav.data.columns` on one
  clock: acceleration (``ax``, ``acc_x_g``; or linear acceleration plus ``grav_x``..), gyroscope (``gx_rad_s``,
  ``gyro_x_dps``; the unit must be named), quaternion (``qw, qx, qy, qz`` in any order, taken as device ->
  level with z up; numbered parts ``q0..q3`` are refused: they do not say which is w).

Sensors on other clocks are put on the accelerometer's: the gyroscope linearly, the quaternion by normalised
linear interpolation (signs made continuous first); the record covers the time every sensor covers. A
quaternion is used only where the data agree with its stated convention: the mean of the accelerometer turned
by it points up within :data:`UP_TOL_DEG`, and where the gyroscope turns enough to tell, the rate the
quaternions imply matches the gyroscope's within :data:`RATE_TOL`; else the record is read without it (the
gyroscope levels it) and the note says which evidence refused it.
"""

from __future__ import annotations

import io
import os
import re
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from accelnav.data import columns as cr
from accelnav.errors import UserError
from accelnav.fileio import check_input, excerpt, input_limit
from accelnav.level import G, ImuRecord, level_frame, rotate
from accelnav.level.quat import qmul

UP_TOL_DEG = 5.0  # the accelerometer's mean turned by the orientation: this close to up, else the quaternion is out
RATE_TOL = 0.5  # rms of (quaternion rate - gyroscope) over the gyroscope's rms rate, where that rate tells
RATE_TELLS = 0.1  # rad/s rms: a gyroscope turning less cannot tell a quaternion's convention
TEXT_SHARE = 4  # a log's text may be a quarter of the input limit (its numbers take up to about 3x)
SENSOR_LOGGER_FILES = ("totalacceleration.csv", "accelerometer.csv", "gravity.csv", "gyroscope.csv",
                       "orientation.csv", "metadata.csv")  # fmt: skip


GRAVITY_BAND = (0.7, 1.3)  # a generic CSV's accelerometer carries gravity: its median |a| within this many g


class NotLevelled(UserError):
    """A generic CSV whose acceleration carries no gravity: not a body-frame accelerometer to level (the
    recording reader reads it as level axes instead, saying so)."""


@dataclass(frozen=True)
class _Series:
    """One sensor as its file gave it: time [s] and values (N, k), named for messages."""

    name: str
    t: np.ndarray
    v: np.ndarray


# --- the entry points -------------------------------------------------------------------------------------------


def read_imu(path: str | os.PathLike[str], *, unit: str | None = None) -> ImuRecord:
    """The IMU record of a phone logger's export or a generic IMU CSV (see the module notes). ``unit``: the
    acceleration's unit where a generic CSV's names say none (g, mg, m/s^2). One-line UserError for anything
    the reader cannot establish."""
    src = str(path)
    kind, files = _open(path)
    reader = {"sensor-logger": _sensor_logger, "phyphox": _phyphox, "physics-toolbox": _physics_toolbox,
              "sensorlog": _sensorlog, "imu-csv": _generic}[kind]  # fmt: skip
    return reader(src, files, unit)


def imu_from_frame(frame, *, source: str = "<arrays>", unit: str | None = None) -> ImuRecord:
    """The IMU record of named columns in memory (a pandas DataFrame or a mapping of arrays) by the generic
    column rules: a time column (``t``, ``time_ms``, datetime64), acceleration, gyroscope and quaternion
    columns named as a generic IMU CSV names them."""
    if hasattr(frame, "columns") and hasattr(frame, "index"):
        source = "<DataFrame>" if source == "<arrays>" else source
        cols = {str(c): np.asarray(frame[c]) for c in frame.columns}
        if frame.index.name is not None and str(frame.index.name) not in cols:
            cols = {str(frame.index.name): np.asarray(frame.index), **cols}
    elif isinstance(frame, Mapping):
        cols = {str(k): np.asarray(v) for k, v in frame.items()}
    else:
        raise UserError(f"imu_from_frame: got a {type(frame).__name__}; accepted: a DataFrame or a mapping of arrays")
    names = list(cols)
    tcol = cr.pick_time(names) or next((c for c in names if cols[c].dtype.kind in "Mm"), None)
    if tcol is None:
        raise UserError(f"{source}: no time column (t, time, time_ms, ...); columns: {_names(names)}")
    raw = cols[tcol].reshape(-1)
    if raw.dtype.kind in "Mm":  # datetime64 (since the epoch) or timedelta64: seconds
        t = raw.astype("datetime64[ns]" if raw.dtype.kind == "M" else "timedelta64[ns]").view(np.int64) * 1e-9
    else:
        t = _floats(source, tcol, raw) * cr.TIME_SCALE[cr.time_unit_of(tcol) or "s"]
    table = {c: _floats(source, c, cols[c].reshape(-1)) for c in names if c != tcol and cols[c].dtype.kind in "biuf"}
    return _generic_columns(source, t, tcol, table, unit)


def sniff(path: str | os.PathLike[str]) -> str | None:
    """The IMU log format of ``path`` (sensor-logger, phyphox, physics-toolbox, sensorlog, imu-csv) from its
    names and header alone, else None (a plain recording, a run file, a log: not this reader's)."""
    try:
        return _kind(Path(path), _header_only=True)[0]
    except (UserError, OSError):
        return None


def level_recording(path, *, axes=None, unit=None, model_axes=None, level: bool = True):
    """(t, acceleration (N, k), axis names, notes) of an IMU log: levelled by :func:`accelnav.level.level_frame`
    (x, y horizontal, z up, gravity removed; the notes end with its summary), or with ``level`` False its
    accelerometer in the device's own axes as recorded (gravity in). The axes: those ``axes`` name (x, y, z),
    else the model's when they are among them, else all three."""
    imu = read_imu(path, unit=unit)
    names = ["x", "y", "z"]
    if axes:
        bad = [a for a in axes if a not in names]
        if bad:
            raise UserError(f"--axis {bad[0]}: {path} is an IMU log, read into axes x, y, z; choose among them")
        chosen = list(axes)
    elif model_axes and set(model_axes) <= set(names):
        chosen = list(model_axes)
    else:
        chosen = names
    pick = [names.index(a) for a in chosen]
    if not level:
        said = (f"{imu.source}: axes {', '.join(chosen)} in the device's own frame, gravity in, not levelled: at rest "
                "an attitude filter aligns gravity with what the accelerometer reads, so levelling would hide each "
                "axis' bias in the attitude")  # fmt: skip
        return imu.t, imu.acc[:, pick], chosen, imu.notes + (said,)
    res = level_frame(imu)
    said = f"{imu.source}: levelled ({res.summary()}); axes {', '.join(chosen)} of the level frame (x, y horizontal, "
    said += "x along the device's first heading, z up), gravity removed"
    return res.t, res.acc[:, pick], chosen, imu.notes + res.notes + (said,)


# --- finding the files ----------------------------------------------------------------------------------------------


def _open(path) -> tuple[str, dict[str, str]]:
    """(format, {lower-case file name: text}) of ``path``: every text a reader may need, read with bounds."""
    kind, files = _kind(Path(path), _header_only=False)
    if kind is None:
        raise UserError(
            f"{path}: not an IMU log this reader knows (Sensor Logger, phyphox, Physics Toolbox, SensorLog, or a CSV "
            "with acceleration and gyroscope or quaternion columns)"
        )
    return kind, files


def _kind(path: Path, _header_only: bool) -> tuple[str | None, dict[str, str]]:
    """The format and the texts (only the first lines of each with ``_header_only``)."""
    if path.is_dir():
        files = {}
        for p in sorted(path.iterdir()):
            if p.name.lower() in SENSOR_LOGGER_FILES or p.name.lower() in _PHYPHOX_FILES:
                files[p.name.lower()] = _text(check_input(p), _header_only)
                held = sum(map(len, files.values()))
                if not _header_only and held > _cap():  # the bound is on the folder's texts together
                    _too_much(str(path), _cap())
        return _folder_kind(files), files
    check_input(path)
    with open(path, "rb") as fh:
        magic = fh.read(4)
    if magic.startswith(b"PK"):
        files = _zip_texts(path, _header_only)
        return _folder_kind(files), files
    text = _text(path, _header_only)
    head = _header_line(text)
    kind = _csv_kind(head[1]) if head else None
    return kind, {path.name.lower(): text}


_PHYPHOX_FILES = ("accelerometer.csv", "linear accelerometer.csv", "gyroscope.csv")


def _folder_kind(files: dict[str, str]) -> str | None:
    """Sensor Logger when any of its files has its clock (``seconds_elapsed``); phyphox when a sensor file has
    a time column that says its unit (``Time (s)``); else None."""
    heads = {name: _header_line(text) for name, text in files.items()}
    cols = {name: [c.lower() for c in h[1]] for name, h in heads.items() if h}
    if any("seconds_elapsed" in c for c in cols.values()):
        return "sensor-logger"
    if any(cr.time_unit_of(c) for name in _PHYPHOX_FILES for c in cols.get(name, [])):
        return "phyphox"
    return None


def _csv_kind(cols: list[str]) -> str | None:
    low = [c.lower() for c in cols]
    if any(c.startswith("accelerometeracceleration") or c.startswith("motionuseracceleration") for c in low):
        return "sensorlog"
    if {"gfx", "gfy", "gfz"} <= {c.replace(" ", "") for c in low}:
        return "physics-toolbox"
    acc = [c for c in cols if cr.axis_of(c) or cr.linear_axis_of(c)]
    turn = [c for c in cols if cr.gyro_axis_of(c) or cr.quat_part_of(c)]
    return "imu-csv" if acc and turn else None


def _cap() -> int:
    return input_limit() // TEXT_SHARE


def _too_much(src: str, cap: int) -> None:
    raise UserError(
        f"{src}: more than {cap >> 20} MiB of text; an IMU log is read whole, its text at most a quarter of the "
        "input limit (ACCELNAV_MAX_INPUT_BYTES): cut the recording"
    )


def _decode(data: bytes, src: str, cap: int) -> str:
    if len(data) > cap:
        _too_much(src, cap)
    if b"\0" in data:
        raise UserError(f"{src}: holds a NUL byte: binary data, not CSV text")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise UserError(f"{src}: not UTF-8 text; accepted: CSV text") from None


def _text(path: Path, header_only: bool = False) -> str:
    import gzip

    src = str(path)
    cap = (1 << 16) if header_only else _cap()
    try:
        with open(path, "rb") as fh:
            gz = fh.read(2) == b"\x1f\x8b"
        with gzip.open(path, "rb") if gz else open(path, "rb") as fh:
            data = fh.read(cap + 1)
    except (OSError, EOFError) as exc:
        raise UserError(f"{src}: cannot read: {excerpt(str(exc))}") from None
    if header_only:
        data = data[:cap]
        return data[: data.rfind(b"\n") + 1 or len(data)].decode("utf-8-sig", errors="replace")
    return _decode(data, src, cap)


def _zip_texts(path: Path, header_only: bool) -> dict[str, str]:
    """The zip's members a reader knows, by lower-case base name, read in memory within the cap (the sizes its
    headers declare first, then what inflates, whatever they declared)."""
    src = str(path)
    cap = (1 << 16) if header_only else _cap()
    wanted = set(SENSOR_LOGGER_FILES) | set(_PHYPHOX_FILES)
    out: dict[str, str] = {}
    try:
        with zipfile.ZipFile(path) as zf:
            infos = [i for i in zf.infolist() if not i.is_dir() and Path(i.filename).name.lower() in wanted]
            total = sum(i.file_size for i in infos)
            if not header_only and total > cap:
                raise UserError(
                    f"{src}: its sensor files hold {total >> 20} MiB of text; an IMU log is read whole, at most "
                    f"{cap >> 20} MiB (a quarter of ACCELNAV_MAX_INPUT_BYTES): cut the recording"
                )
            held = 0
            for info in infos:
                name = Path(info.filename).name.lower()
                if name in out:
                    raise UserError(f"{src}: two members named {excerpt(name)}; one recording per zip")
                with zf.open(info) as fh:
                    data = fh.read(cap + 1 - held)  # what inflates, whatever the headers declared
                held += 0 if header_only else len(data)
                where = f"{src}:{excerpt(info.filename, 60)}"
                if header_only:
                    data = data[:cap]
                    out[name] = data[: data.rfind(b"\n") + 1 or len(data)].decode("utf-8-sig", errors="replace")
                else:
                    out[name] = _decode(data, where, cap - held + len(data))
    except (zipfile.BadZipFile, zipfile.LargeZipFile, RuntimeError, NotImplementedError, OSError, EOFError) as exc:
        raise UserError(f"{src}: not a readable zip: {excerpt(str(exc))}") from None
    return out


# --- reading a CSV's numbers ----------------------------------------------------------------------------------------


def _header_line(text: str) -> tuple[int, list[str], str] | None:
    """(line index, column names, delimiter) of the first line that is not blank or a ``#`` comment."""
    for i, line in enumerate(text.splitlines()):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        delim = max((",", ";", "\t"), key=line.count)
        delim = delim if line.count(delim) else ","
        return i, [c.strip().strip('"').strip() for c in line.split(delim)], delim
    return None


def _csv(src: str, text: str, wanted: list[str], strings: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """The columns ``wanted`` (names as the header spells them) of a CSV text, float64; ``strings`` as text."""
    head = _header_line(text)
    if head is None:
        raise UserError(f"{src}: no header row (the file is empty)")
    at, cols, delim = head
    missing = [w for w in wanted if w not in cols]
    if missing:
        raise UserError(f"{src}: no column {excerpt(missing[0])}; columns: {_names(cols)}")
    body = text.split("\n", at + 1)[at + 1] if text.count("\n") > at else ""
    if delim != ",":
        body = body.replace(",", ".")  # ';' or tab between fields: a comma is a decimal comma
    out = {}
    numbers = [w for w in wanted if w not in strings]
    for group, kind in ((numbers, np.float64), ([w for w in wanted if w in strings], str)):
        if not group:
            continue
        use = [cols.index(w) for w in group]
        try:  # one pass over the text for every numeric column
            a = np.loadtxt(io.StringIO(body), delimiter=delim, usecols=use, dtype=kind, comments="#", quotechar='"',
                           ndmin=2)  # fmt: skip
        except ValueError as exc:
            said = str(exc).splitlines()[0] if str(exc) else "not a number"
            m = re.search(r"column (\d+)", said)
            name = cols[int(m.group(1)) - 1] if m and 0 < int(m.group(1)) <= len(cols) else ", ".join(group)
            raise UserError(f"{src}: column {excerpt(name, 40)}: {excerpt(said, 120)}") from None
        out.update({w: a[:, k] for k, w in enumerate(group)})
    bad = [w for w in numbers if not np.all(np.isfinite(out[w]))]
    if bad:
        k = int(np.argmax(~np.isfinite(out[bad[0]])))
        raise UserError(f"{src}: column {excerpt(bad[0], 40)}, data row {k + 1} is not a finite number")
    n = {len(a) for a in out.values()}
    if len(n) > 1 or not n or min(n) < 2:
        raise UserError(f"{src}: {min(n) if n else 0} data rows; a recording needs many more")
    return out


def _floats(src: str, name: str, raw: np.ndarray) -> np.ndarray:
    try:
        a = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError):
        raise UserError(f"{src}: column {excerpt(name, 40)} is not numbers") from None
    if not np.all(np.isfinite(a)):
        raise UserError(f"{src}: column {excerpt(name, 40)} holds a value that is not a finite number")
    return a


def _names(cols) -> str:
    text = ", ".join(c if len(c) <= 40 else c[:37] + "..." for c in cols)
    return text if len(text) <= 320 else text[:317] + "..."


def _xyz(src: str, cols: list[str], axis_of) -> list[str] | None:
    """The columns holding x, y and z by ``axis_of`` (in that order), None when there are none; a partial set
    or an axis twice is refused."""
    by = {}
    for c in cols:
        a = axis_of(c)
        if a in ("x", "y", "z"):
            if a in by:
                raise UserError(f"{src}: two columns for axis {a}: {excerpt(by[a], 40)} and {excerpt(c, 40)}")
            by[a] = c
    if not by:
        return None
    if len(by) < 3:
        raise UserError(f"{src}: columns for axes {', '.join(sorted(by))} only; an IMU needs x, y and z")
    return [by["x"], by["y"], by["z"]]


# --- the formats ---------------------------------------------------------------------------------------------------


def _sensor_logger(src: str, files: dict[str, str], unit) -> ImuRecord:
    notes = []

    def series(name: str, parts=("x", "y", "z")) -> _Series | None:
        text = files.get(name)
        if text is None:
            return None
        where = f"{src}:{name}"
        cols = _csv(where, text, ["time", *parts])
        return _Series(name, cols["time"] * 1e-9, np.column_stack([cols[p] for p in parts]))

    platform = _platform(src, files.get("metadata.csv"))
    total, user, grav = series("totalacceleration.csv"), series("accelerometer.csv"), series("gravity.csv")
    gyro = series("gyroscope.csv")
    quat = series("orientation.csv", ("qw", "qx", "qy", "qz"))
    quat_said = "Orientation.csv (qw, qx, qy, qz): device -> " + (
        "x-north-z-vertical (CoreMotion's attitude)"
        if platform == "ios"
        else "east-north-up (Android's rotation vector)"
    )
    sign = 1.0
    if total is not None:
        acc = total
        notes.append(f"{src}: accelerometer from TotalAcceleration.csv (gravity included), m/s^2")
    elif user is not None and grav is not None:
        acc = _Series("accelerometer.csv + gravity.csv", user.t, user.v + _on_clock(grav, user.t, src, user.name))
        how = "Accelerometer.csv (gravity removed) + Gravity.csv"
        if platform == "ios":
            sign, why = _ios_sign(acc, quat)
            notes.append(f"{src}: accelerometer = {how}, {why}")
        else:
            notes.append(f"{src}: accelerometer = {how} (Android's sign)")
    elif user is not None:
        raise UserError(
            f"{src}: Accelerometer.csv has gravity removed and there is no TotalAcceleration.csv or Gravity.csv to "
            "put it back: the level frame needs the accelerometer with gravity (enable Gravity in Sensor Logger)"
        )
    else:
        raise UserError(f"{src}: no TotalAcceleration.csv and no Accelerometer.csv: no accelerometer in this export")
    acc = _Series(acc.name, acc.t, sign * acc.v)
    return _assemble(src + " (Sensor Logger)", acc, gyro, quat, quat_said, notes)


def _platform(src: str, text: str | None) -> str | None:
    """Metadata.csv's platform (ios, android), else None."""
    if text is None:
        return None
    head = _header_line(text)
    if head is None or "platform" not in [c.lower() for c in head[1]]:
        return None
    at, cols, delim = head
    rows = [r for r in text.splitlines()[at + 1 :] if r.strip()]
    if not rows:
        return None
    cells = rows[0].split(delim)
    j = [c.lower() for c in cols].index("platform")
    value = cells[j].strip().strip('"').lower() if j < len(cells) else ""
    return value if value in ("ios", "android") else None


def _ios_sign(acc: _Series, quat: _Series | None) -> tuple[float, str]:
    """The sign of an iOS export's acceleration: CoreMotion's (negated here) unless the orientation shows the
    app standardised it (its mean gravity turned up, not down)."""
    if quat is None:
        return -1.0, (
            "iOS with no orientation to tell whether 'Standardise Units & Frames' was on: taken as off (the app's "
            "default: CoreMotion's sign, negated here)"
        )
    q = _on_clock(quat, acc.t, "", quat.name, unit_rows=True)
    up = float(np.mean(rotate(q, acc.v)[:, 2]))
    if up > 0:
        return 1.0, "iOS with Android's sign ('Standardise Units & Frames' on: the orientation turns gravity up)"
    return -1.0, "iOS with CoreMotion's sign, negated here (the orientation turns the sum down)"


def _phyphox(src: str, files: dict[str, str], unit) -> ImuRecord:
    notes = [f"{src}: phyphox sensors, Android's sign on both platforms"]

    def series(name: str, axis_of, rate: bool) -> _Series | None:
        text = files.get(name)
        if text is None:
            return None
        where = f"{src}:{name}"
        head = _header_line(text)
        cols = head[1] if head else []
        tcol = cr.pick_time(cols)
        xyz = _xyz(where, cols, axis_of)
        if tcol is None or xyz is None:
            raise UserError(f"{where}: expected phyphox's columns (Time (s), x, y, z); columns: {_names(cols)}")
        data = _csv(where, text, [tcol, *xyz])
        scale = _rate_scale(where, xyz) if rate else _acc_scale(where, xyz, unit)
        t = data[tcol] * cr.TIME_SCALE[cr.time_unit_of(tcol) or "s"]
        return _Series(name, t, np.column_stack([data[c] for c in xyz]) * scale)

    acc = series("accelerometer.csv", cr.axis_of, False)
    if acc is None:
        if "linear accelerometer.csv" in files:
            raise UserError(
                f"{src}: only Linear Accelerometer.csv (gravity removed): the level frame needs phyphox's "
                "'Acceleration with g' sensor (Accelerometer.csv)"
            )
        raise UserError(f"{src}: no Accelerometer.csv in this phyphox export")
    gyro = series("gyroscope.csv", cr.gyro_axis_of, True)
    return _assemble(src + " (phyphox)", acc, gyro, None, "", notes)


def _physics_toolbox(src: str, files: dict[str, str], unit) -> ImuRecord:
    (text,) = files.values()
    at, cols, _ = _header_line(text)
    key = {c.replace(" ", "").lower(): c for c in cols}
    tcol = key.get("time")
    if tcol is None:
        raise UserError(f"{src}: no 'time' column; columns: {_names(cols)}")
    gf = [key["gfx"], key["gfy"], key["gfz"]]
    w = [key.get(k) for k in ("wx", "wy", "wz")]
    first = next((r for r in text.splitlines()[at + 1 :] if r.strip()), "")
    clock = ":" in first.split(_header_line(text)[2])[cols.index(tcol)] if first else False
    data = _csv(src, text, [tcol, *gf, *[c for c in w if c]], strings=(tcol,) if clock else ())
    t = _clock_seconds(src, data[tcol]) if clock else data[tcol]
    notes = [f"{src}: accelerometer from gFx, gFy, gFz (the g-force: gravity included, in g, Android's sign)"]
    if any(c.lower() in ("azimuth", "pitch", "roll") for c in cols):
        notes.append(
            f"{src}: its Azimuth, Pitch, Roll not used: the export does not state their rotation order and reference, "
            "so the gyroscope levels it"
        )
    acc = _Series("g-force", t, np.column_stack([data[c] for c in gf]) * G)
    gyro = _Series("gyroscope", t, np.column_stack([data[c] for c in w])) if all(w) else None
    return _assemble(src + " (Physics Toolbox)", acc, gyro, None, "", notes)


def _clock_seconds(src: str, cells: np.ndarray) -> np.ndarray:
    """Seconds of clock cells ``HH:MM:SS:mmm`` or ``HH:MM:SS.fff``, a day added where the clock passes midnight."""
    out = np.empty(len(cells))
    for i, cell in enumerate(cells):
        m = re.fullmatch(r"\s*(\d{1,2}):(\d{2}):(\d{2})(?:[:.](\d{1,6}))?\s*", str(cell))
        if not m:
            raise UserError(f"{src}: data row {i + 1}: time {excerpt(str(cell), 30)} is not a clock (HH:MM:SS:mmm)")
        h, mi, s, frac = m.groups()
        ms = int(frac) / 10 ** len(frac) if frac else 0.0  # the digits after the seconds: a fraction of one
        out[i] = int(h) * 3600 + int(mi) * 60 + int(s) + ms
    back = np.diff(out) < -43200  # midnight: the clock starts again
    return out + 86400.0 * np.concatenate(([0], np.cumsum(back)))


def _sensorlog(src: str, files: dict[str, str], unit) -> ImuRecord:
    (text,) = files.values()
    cols = _header_line(text)[1]
    by = {re.sub(r"\(.*\)$", "", c).strip().lower(): c for c in cols}

    def pick(stamp: str, names: list[str], scale: float, what: str) -> _Series | None:
        if not all(n.lower() in by for n in names):
            return None
        said = {re.search(r"\(([^)]*)\)$", by[n.lower()]) for n in names}
        units = {m.group(1) if m else "" for m in said}
        expected = {"G"} if scale != 1.0 else {"rad/s", "R"}
        if not units <= expected:
            raise UserError(f"{src}: {what} columns in {', '.join(sorted(units))}; SensorLog writes {min(expected)}")
        if stamp.lower() not in by:
            raise UserError(f"{src}: {what} columns without their clock {stamp}")
        data = _csv(src, text, [by[stamp.lower()], *[by[n.lower()] for n in names]])
        return _Series(what, data[by[stamp.lower()]], np.column_stack([data[by[n.lower()]] for n in names]) * scale)

    xyz = ("X", "Y", "Z")
    acc = pick("accelerometerTimestamp_sinceReboot", [f"accelerometerAcceleration{a}" for a in xyz], -G,
               "accelerometer")  # fmt: skip
    notes = [f"{src}: accelerometer in g with CoreMotion's sign (an inertial force), negated here"]
    if acc is None:
        user = pick("motionTimestamp_sinceReboot", [f"motionUserAcceleration{a}" for a in xyz], -G, "motion")
        grav = pick("motionTimestamp_sinceReboot", [f"motionGravity{a}" for a in xyz], -G, "motion")
        if user is None or grav is None:
            raise UserError(f"{src}: no accelerometerAcceleration or motionUserAcceleration + motionGravity columns")
        acc = _Series("motion", user.t, user.v + grav.v)
        notes = [f"{src}: accelerometer = motionUserAcceleration + motionGravity, in g, CoreMotion's sign negated"]
    gyro = pick("gyroTimestamp_sinceReboot", [f"gyroRotation{a}" for a in xyz], 1.0, "gyroscope")
    quat = pick("motionTimestamp_sinceReboot", [f"motionQuaternion{a}" for a in ("W", "X", "Y", "Z")], 1.0,
                "motion quaternion")  # fmt: skip
    said = "motionQuaternionW, X, Y, Z: device -> CoreMotion's reference frame (z vertical)"
    return _assemble(src + " (SensorLog)", acc, gyro, quat, said, notes)


def _generic(src: str, files: dict[str, str], unit) -> ImuRecord:
    (text,) = files.values()
    cols = _header_line(text)[1]
    tcol = cr.pick_time(cols)
    if tcol is None:
        raise UserError(f"{src}: no time column (t, time, time_ms, ...); columns: {_names(cols)}")
    wanted = [c for c in cols if c != tcol and _imu_column(c)]
    data = _csv(src, text, [tcol, *wanted])
    tu = cr.time_unit_of(tcol)
    t = data.pop(tcol)
    if tu is None:  # Unix time by its numbers (the clock rule of accelnav.data.columns), else seconds
        tu = cr.epoch_unit(src, tcol, float(t[0]), float(np.median(np.diff(t))))[0] or "s"
    return _generic_columns(src, t * cr.TIME_SCALE[tu], tcol, data, unit)


def _imu_column(c: str) -> bool:
    return bool(cr.axis_of(c) or cr.linear_axis_of(c) or cr.gravity_axis_of(c) or cr.gyro_axis_of(c)
                or cr.quat_part_of(c))  # fmt: skip


def _generic_columns(src: str, t: np.ndarray, tcol: str, table: dict[str, np.ndarray], unit) -> ImuRecord:
    """The generic rules over named columns on one clock ``t`` [s]."""
    names = list(table)
    gravity = _xyz(src, names, cr.gravity_axis_of)
    linear = _xyz(src, names, cr.linear_axis_of)
    plain = _xyz(src, [c for c in names if not cr.is_linear(c) and not cr.gravity_axis_of(c)], cr.axis_of)
    notes = []
    if plain is not None:
        acc = np.column_stack([table[c] for c in plain]) * _acc_scale(src, plain, unit)
        notes.append(f"{src}: accelerometer from {', '.join(plain)} (gravity included, Android's sign)")
    elif linear is not None and gravity is not None:
        acc = np.column_stack([table[c] for c in linear]) * _acc_scale(src, linear, unit)
        acc = acc + np.column_stack([table[c] for c in gravity]) * _acc_scale(src, gravity, unit)
        notes.append(f"{src}: accelerometer = {', '.join(linear)} (gravity removed) + {', '.join(gravity)}")
    elif linear is not None:
        raise UserError(
            f"{src}: {', '.join(linear)} have gravity removed and there are no gravity columns (grav_x, ...): the "
            "level frame needs the accelerometer with gravity"
        )
    else:
        raise UserError(f"{src}: no acceleration columns (ax, acc_x_g, ...); columns: {_names(names)}")
    mag = float(np.median(np.linalg.norm(acc, axis=1)))
    if not GRAVITY_BAND[0] * G <= mag <= GRAVITY_BAND[1] * G:
        raise NotLevelled(
            f"{src}: its acceleration holds no gravity (median |a| {mag:.3g} m/s^2, 1 g is {G:.5g}): not a body-frame "
            "accelerometer to level"
        )
    gx = _xyz(src, names, cr.gyro_axis_of)
    gyro = None if gx is None else np.column_stack([table[c] for c in gx]) * _rate_scale(src, gx)
    parts = {cr.quat_part_of(c): c for c in names if cr.quat_part_of(c)}
    quat = None
    if parts:
        if set(parts) & set("0123"):
            raise UserError(
                f"{src}: quaternion columns numbered ({', '.join(parts.values())}) do not say which part is w: "
                "name them qw, qx, qy, qz"
            )
        if set(parts) != set("wxyz"):
            raise UserError(f"{src}: quaternion parts {', '.join(sorted(parts))} only; a quaternion needs w, x, y, z")
        quat = _Series("quaternion", t, np.column_stack([table[parts[p]] for p in "wxyz"]))
    said = f"{', '.join(parts[p] for p in 'wxyz')}: device -> level frame, z up (taken as named)" if parts else ""
    series = _Series(f"accelerometer ({tcol})", t, acc)
    g = None if gyro is None else _Series("gyroscope", t, gyro)
    return _assemble(src, series, g, quat, said, notes)


def _acc_scale(src: str, cols: list[str], unit: str | None) -> float:
    units = {cr.unit_of(c) for c in cols}
    if len(units) > 1:
        raise UserError(f"{src}: columns {', '.join(cols)} in mixed units ({', '.join(sorted(map(str, units)))})")
    (u,) = units
    if u is None:
        if unit is None:
            raise UserError(f"{src}: columns {', '.join(cols)} do not say their unit (ax_g, acc_x_m_s2); give --unit")
        u = cr.parse_unit(unit)
    elif unit is not None and cr.parse_unit(unit) != u:
        raise UserError(f"{src}: --unit {unit} contradicts {cols[0]!r}, whose name says {u}")
    if u == "counts":
        raise UserError(f"{src}: raw counts in an IMU log; give the acceleration in g or m/s^2")
    return cr.UNITS[u]


def _rate_scale(src: str, cols: list[str]) -> float:
    units = {cr.rate_unit_of(c) for c in cols}
    if len(units) > 1:
        raise UserError(f"{src}: gyroscope columns {', '.join(cols)} in mixed units")
    (u,) = units
    if u is None:
        raise UserError(
            f"{src}: gyroscope columns {', '.join(cols)} do not say their unit: name them gx_rad_s or gx_dps "
            "(rad/s, deg/s)"
        )
    return cr.RATE_UNITS[u]


# --- one clock ------------------------------------------------------------------------------------------------------


def _increasing(src: str, s: _Series) -> tuple[_Series, int]:
    """``s`` with samples that repeat the time stamp before dropped (loggers repeat a sensor that has not
    updated); time going back is refused."""
    dt = np.diff(s.t)
    if np.any(dt < 0):
        k = int(np.argmax(dt < 0))
        raise UserError(f"{src}: {s.name}: time goes back at sample {k + 1} ({s.t[k]:.9g} s, then {s.t[k + 1]:.9g} s)")
    keep = np.concatenate(([True], dt > 0))
    return _Series(s.name, s.t[keep], s.v[keep]), int((~keep).sum())


def _on_clock(s: _Series, t: np.ndarray, src: str, onto: str, unit_rows: bool = False) -> np.ndarray:
    """``s`` on the times ``t`` (within its span): linear interpolation, or for quaternions (``unit_rows``)
    normalised linear interpolation after making consecutive signs agree."""
    s, _ = _increasing(src, s)
    v = s.v
    if unit_rows:
        n = np.linalg.norm(v, axis=1)
        if np.any(n < 1e-6):
            k = int(np.argmax(n < 1e-6))
            raise UserError(f"{src}: {s.name}: a quaternion of zero length at t = {s.t[k]:.9g} s")
        v = v / n[:, None]
        flip = np.cumprod(np.where(np.sum(v[1:] * v[:-1], axis=1) < 0, -1.0, 1.0))
        v = v * np.concatenate(([1.0], flip))[:, None]
    if len(s.t) == len(t) and np.array_equal(s.t, t):
        out = v.copy()
    else:
        out = np.column_stack([np.interp(t, s.t, v[:, j]) for j in range(v.shape[1])])
    if unit_rows:
        out /= np.linalg.norm(out, axis=1, keepdims=True)
    return out


def _assemble(src: str, acc: _Series, gyro: _Series | None, quat: _Series | None, quat_said: str, notes) -> ImuRecord:
    """The record on the accelerometer's clock, over the span every sensor covers; the quaternion checked."""
    notes = list(notes)
    acc, dup = _increasing(src, acc)
    if dup:
        notes.append(f"{src}: {dup} accelerometer samples repeating the time before them dropped")
    others = [s for s in (gyro, quat) if s is not None]
    lo = max([acc.t[0]] + [s.t[0] for s in others])
    hi = min([acc.t[-1]] + [s.t[-1] for s in others])
    if hi <= lo:
        spans = "; ".join(f"{s.name} {s.t[0]:.6g}..{s.t[-1]:.6g} s" for s in (acc, *others))
        raise UserError(f"{src}: the sensors' clocks never overlap ({spans})")
    keep = (acc.t >= lo) & (acc.t <= hi)
    if keep.sum() < 2:
        raise UserError(f"{src}: the sensors' clocks overlap for {keep.sum()} accelerometer samples only")
    if not keep.all():
        notes.append(
            f"{src}: {int((~keep).sum())} accelerometer samples outside the span every sensor covers left out "
            f"({lo - acc.t[0]:.3g} s at the start, {acc.t[-1] - hi:.3g} s at the end)"
        )
    t, f = acc.t[keep], acc.v[keep]
    g = q = None
    if gyro is not None:
        g = _on_clock(gyro, t, src, acc.name)
        if not np.array_equal(gyro.t, acc.t):
            notes.append(
                f"{src}: the gyroscope's own clock ({len(gyro.t)} samples) put on the accelerometer's, linearly"
            )
    if quat is not None:
        q = _on_clock(quat, t, src, acc.name, unit_rows=True)
        if not np.array_equal(quat.t, acc.t):
            notes.append(
                f"{src}: the orientation's own clock ({len(quat.t)} samples) put on the accelerometer's (normalised "
                "linear interpolation)"
            )
        q, said = _check_quat(t, f, g, q, quat_said)
        notes.append(f"{src}: {said}")
    t0 = float(t[0])
    if t0 > 946684800.0:  # a calendar's clock (Unix time): say when, and count from the first sample
        import datetime

        when = datetime.datetime.fromtimestamp(t0, datetime.UTC).strftime("%Y-%m-%d %H:%M:%S")
        notes.append(f"{src}: time counted from the first accelerometer sample ({when} UTC)")
    return ImuRecord(t - t0, f, gyro=g, quat=q, source=src, notes=tuple(notes))


def _check_quat(t, f, gyro, q, said: str) -> tuple[np.ndarray | None, str]:
    """(q, what decided) when the data agree with the stated convention, else (None, why not)."""
    m = rotate(q, f).mean(axis=0)
    off = float(np.degrees(np.arccos(np.clip(m[2] / max(np.linalg.norm(m), 1e-12), -1.0, 1.0))))
    if off > UP_TOL_DEG:
        return None, (
            f"orientation not used: by its stated convention ({said}) the mean accelerometer points {off:.3g} deg "
            f"from up (> {UP_TOL_DEG:g}): the convention does not hold for this file, so the gyroscope levels it"
        )
    rate = ""
    if gyro is not None:
        dq = qmul(q[:-1] * [1.0, -1.0, -1.0, -1.0], q[1:])  # conj(q_k) q_k+1: the turn in the device's axes
        dq *= np.sign(dq[:, :1] + (dq[:, :1] == 0))
        omega = 2.0 * dq[:, 1:] / np.diff(t)[:, None]
        mid = 0.5 * (gyro[1:] + gyro[:-1])
        spin = float(np.sqrt(np.mean(np.sum(mid**2, axis=1))))
        if spin >= RATE_TELLS:
            err = float(np.sqrt(np.mean(np.sum((omega - mid) ** 2, axis=1)))) / spin
            if err > RATE_TOL:
                return None, (
                    f"orientation not used: the turn its quaternions imply ({said}) differs from the gyroscope's by "
                    f"{err:.2g} of the gyroscope's rms rate (> {RATE_TOL:g}): the convention does not hold, so the "
                    "gyroscope levels it"
                )
            rate = f", its turn the gyroscope's within {err:.2g} of the rms rate"
        else:
            rate = f"; the gyroscope turns too little ({spin:.2g} rad/s rms) to check its rate"
    return q, f"orientation used ({said}): the mean accelerometer turned by it is {off:.2g} deg from up{rate}"


def write_level_csv(path, result, *, inputs=()) -> Path:
    """Write a :class:`accelnav.level.LevelResult` as the recording ``smooth`` reads: ``t, x_accel, y_accel,
    z_accel`` (s; m/s^2 in the level frame, gravity removed), by the output rule (accelnav.fileio)."""
    from accelnav.fileio import atomic_output

    table = np.column_stack([result.t, result.acc])
    with atomic_output(path, "w", "--out", inputs=inputs) as fh:
        fh.write("t,x_accel,y_accel,z_accel\n")
        np.savetxt(fh, table, delimiter=",", fmt=["%.9f", "%.7g", "%.7g", "%.7g"])
    return Path(path)
