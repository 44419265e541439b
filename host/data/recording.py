"""Read a stationary recording (CSV, gzip CSV, NPZ) and refuse what the bias fit cannot use.

Formats
-------
* **CSV** (plain or gzip, told apart by content, not by name): one header
  row of column names, then numbers; ``#`` comment lines before the header
  are skipped; comma, semicolon or tab separated. Which columns are time and
  acceleration, and their units, the names say by the column rules of
  :mod:`accelnav.data.columns` (``t_ms``, ``acc_x_g``, ``ax_m_s2``, ``x``,
  phone apps' ``Linear Acceleration x (m/s^2)``, ``Time (s)``); ``--axis``
  picks columns by name or axis, ``--unit`` serves names that say no unit
  (one that contradicts a name is refused), and a time column whose name says
  no unit is in seconds, or in the unit of Unix time its numbers show. With
  the model's axis names the columns come in the model's order. With ``;`` or
  tab as separator a decimal comma (``0,01188``) is read as a decimal point.
* **NPZ** as written by ``accelnav sim``: ``t`` (N,), ``axis_names``
  (n_axes,), ``accel`` (N, n_axes) in m/s^2, optionally a 0-d
  ``model_toml`` string and a ``clipped`` (N, n_axes) mask. ``accel`` may be
  1-D for one axis; without ``t`` the rate comes from ``rate_hz`` or the
  embedded model.

Refusals (:class:`accelnav.errors.UserError`, one line each, saying where):
unreadable file, missing column, unknown unit, no time and no rate, time not
finite or not increasing, a gap in time, a non-finite sample, too short a
recording, a constant signal, a clipped signal (samples flagged in the file,
at the model's full scale, or piled up on the extreme value as a rail does), a unit no name said that the
data contradict (:func:`check_units`, naming the unit they most likely have).
"""

from __future__ import annotations

import gzip
import io
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from accelnav.data import csvnum
from accelnav.data.columns import (  # the clock's rules (MIN_CLOCK_HZ, epoch_unit) live with the names'
    MIN_CLOCK_HZ,
    TIME_SCALE,
    TIME_UNITS,
    UNITS,
    axis_of,
    epoch_unit,
    parse_unit,
    pick_time,
    time_unit_of,
    unit_of,
)
from accelnav.errors import UserError
from accelnav.fileio import EXCERPT_CHARS, check_input, excerpt, input_limit, load_npz
from accelnav.model.load import G0, ModelError, loads_model
from accelnav.progress import Progress
from accelnav.resources import threads

GAP_FACTOR = 1.5  # a time step longer than this many median steps is a gap
SNAP_TOL = 0.01  # a clock within 1 % of a whole number of Hz (>= 10 Hz) is taken as that nominal rate
MAX_LAG_PERIODS = 5.0  # stamps that jitter more than half a period may still be read by order, within this
# read in the claimed unit, this share of samples beyond the sensor's range (by BEYOND: a clipped sensor sits at
# its rail, it never reads past it) while another unit leaves under 1 % there: the unit is wrong
RAIL_SHARE = 0.05
BEYOND = 1.05
MIN_DURATION_S = 60.0
MIN_SAMPLES = 1000
CHUNK_CHARS = 1 << 18  # CSV text parsed per piece: the reader's memory beyond the numbers it keeps
PARSE_AHEAD = 4  # pieces the C parser reads ahead on other threads (their text and numbers held: ~10 MB)
MAX_LINE_CHARS = 1 << 16  # a longer line is not a CSV row (a binary file, a file without newlines)
PILEUP_FRACTION = 0.005  # an extreme value holding this share of the samples, more than its neighbour: a rail


@dataclass(frozen=True, eq=False)
class Recording:
    """A stationary recording: time [s] and acceleration [m/s^2] of one or more axes."""

    source: str
    t: np.ndarray  # (N,)
    accel: np.ndarray  # (N, n_axes)
    axis_names: tuple[str, ...]
    columns: tuple[str, ...]  # where each axis came from (column or key)
    units: tuple[str, ...]  # the unit each axis was given in
    rate_hz: float
    model_toml: str | None = None
    clipped: np.ndarray | None = None  # (N, n_axes) from the file, if it had one
    lines: np.ndarray | None = None  # (N,) the file line of each sample (CSV only), for messages
    time_unit: str | None = None  # the time column's unit as its name says ("s", "ms", "us"), None: unsaid
    time_column: str | None = None  # where t came from (a CSV column, the NPZ key); None: from the rate
    notes: tuple[str, ...] = ()  # one line each, for the caller to print: how the clock was read
    first: int = 0  # the index in the whole file of sample 0 here (a block of a streamed input)
    unit_from: tuple[str, ...] = ()  # per axis, what said its unit: "name", "--unit", "model" or "file"

    def where(self, k: int) -> str:
        """Where sample k is in the file: its line (CSV) or its index."""
        i = k + self.first
        return f"sample {i} (line {int(self.lines[k])})" if self.lines is not None else f"sample {i}"

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n > 1 else 0.0

    def column(self, axis: str) -> int:
        for i, (name, col) in enumerate(zip(self.axis_names, self.columns, strict=True)):
            if axis in (name, col):
                return i
        raise UserError(f"{self.source}: no axis {axis!r}; the recording has: {', '.join(self.axis_names)}")

    def axis(self, axis: str) -> np.ndarray:
        return self.accel[:, self.column(axis)]


def read_recording(
    path: str | Path,
    *,
    axes: list[str] | None = None,
    unit: str | None = None,
    rate_hz: float | None = None,
    time_column: str | None = None,
    allow_gaps: bool = False,
    time_unit: str | None = None,
    default_unit: str | None = None,
    model_axes: list[str] | None = None,
    level: bool = True,
) -> Recording:
    """Read ``path`` (CSV, gzip CSV or NPZ); see the module notes. Checks the format, not the content.

    A phone or IMU log (:func:`accelnav.data.imu.sniff`) is levelled (:func:`accelnav.data.imu.level_recording`);
    with ``level`` False (a stationary recording for the bias fit) its accelerometer is read in the device's own
    axes: a logger's export through the IMU reader, a generic IMU CSV as any CSV (its acceleration columns).

    ``unit`` is the unit of every acceleration column; without it each column's name says its unit,
    and ``default_unit`` (a calibrated model's) serves a column whose name does not. ``model_axes``: the
    model's axis names; a column named as one is that axis, and the axes come in the model's order.

    ``allow_gaps`` lets gaps in time through (the caller fills them, see :func:`on_grid`). ``time_unit``
    (s, ms, us) is the time column's unit when its name does not say it. ``rate_hz`` with a time column
    is the nominal rate the clock is checked against (and overridden by, see :func:`_check_time`). The
    clock is read as :func:`_check_time` says; ``notes`` of the result tell the caller how, one line each.
    """
    from accelnav.data import imu

    kind = imu.sniff(path)  # a phone or IMU log (body frame, gravity in): levelled first, one reader for every command
    # a generic IMU CSV is read as plain columns for the bias fit, and when --axis names its own columns
    plain = kind == "imu-csv" and (not level or bool(axes) and not set(axes) <= {"x", "y", "z"})
    said = ()
    if kind is not None and not plain:
        try:
            return _levelled(path, axes, unit, rate_hz, time_column, time_unit, allow_gaps, model_axes, level)
        except imu.NotLevelled as exc:
            if kind != "imu-csv":
                raise
            said = (f"{exc}: read as level axes, not levelled",)
    path = check_input(path)  # a regular file: a FIFO or /dev/zero is refused before it is read
    try:
        with path.open("rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror}") from None
    from accelnav.link.logfile import MAGIC

    if head == MAGIC:  # binary: the CSV reader would stop at a NUL byte or at UTF-8, naming neither
        raise UserError(
            f"{path}: a recorder log, not a recording (CSV, gzip CSV or NPZ): export its samples first with "
            f"accelnav log export {path} --out FILE.csv"
        )
    if rate_hz is not None and not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise UserError(f"--rate: got {rate_hz}; accepted: a positive sample rate in Hz")
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise UserError(f"--time-unit: got {time_unit!r}; accepted: {', '.join(TIME_UNITS)}")
    if head.startswith(b"PK"):
        rec = _read_npz(path, axes, unit, rate_hz, default_unit, model_axes)
    else:
        gz = head.startswith(b"\x1f\x8b")
        rec = _read_csv(path, axes, unit, rate_hz, time_column, gz, default_unit, model_axes)
    rec = _check_time(_with_time_unit(rec, time_unit, path), rate_hz, allow_gaps)
    return replace(rec, notes=said + rec.notes) if said else rec


def _levelled(path, axes, unit, rate_hz, time_column, time_unit, allow_gaps, model_axes, level=True) -> Recording:
    """An IMU log as a recording of its level frame (accelnav.data.imu.level_recording): axes x, y, z in m/s^2,
    gravity removed (or the device's axes, with ``level`` False), on the accelerometer's clock; the notes say
    how it was read and levelled."""
    from accelnav.data.imu import level_recording

    for flag, value in (("time-column", time_column), ("time-unit", time_unit)):
        if value is not None:
            raise UserError(f"--{flag}: {path} is an IMU log, whose format says its clocks")
    if rate_hz is not None and not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise UserError(f"--rate: got {rate_hz}; accepted: a positive sample rate in Hz")
    t, acc, names, notes = level_recording(path, axes=axes, unit=unit, model_axes=model_axes, level=level)
    cols = tuple(f"{a}_{'level' if level else 'device'}" for a in names)
    rec = _finish(str(path), t, acc, tuple(names), cols, ("m/s^2",) * len(names), None, None)
    rec = replace(rec, time_unit="s", time_column="t", notes=tuple(notes), unit_from=("name",) * len(names))
    return _check_time(rec, rate_hz, allow_gaps)


# --------------------------------------------------------------------------


def _read_npz(path: Path, axes, unit, rate_hz, default_unit=None, model_axes=None) -> Recording:
    src = str(path)
    data = load_npz(path, src)  # sizes checked before anything is inflated; no pickles
    if "accel" not in data:
        no_input(src, data)
        raise UserError(
            f"{src}: no 'accel' array; keys: {', '.join(sorted(data)) or 'none'} (expected accelnav sim's layout)"
        )
    accel = _numbers(data, "accel", src)
    if accel.ndim == 1:
        accel = accel[:, None]
    if accel.ndim != 2 or accel.shape[0] < 2:
        raise UserError(f"{src}: 'accel' has shape {data['accel'].shape}; accepted: (N,) or (N, n_axes)")
    n, k = accel.shape
    if "axis_names" in data:
        names = tuple(str(s) for s in np.asarray(data["axis_names"]).reshape(-1))
        if len(names) != k:
            raise UserError(f"{src}: {len(names)} axis_names for {k} accel columns")
    else:
        names = tuple(f"a{i}" for i in range(k))
    model_toml = str(data["model_toml"][()]) if "model_toml" in data else None
    clipped = None
    if "clipped" in data:
        clipped = _numbers(data, "clipped", src, bool)
        if clipped.shape != (n, k) and not (k == 1 and clipped.shape == (n,)):  # one flag per sample and axis
            raise UserError(f"{src}: 'clipped' has shape {clipped.shape}; 'accel' has {(n, k)}")
        clipped = clipped.reshape(n, k)
    if "t" in data:
        t = _numbers(data, "t", src).reshape(-1)
        if len(t) != n:
            raise UserError(f"{src}: 't' has {len(t)} samples, 'accel' {n}")
    else:
        rate = rate_hz
        if rate is None and "rate_hz" in data:
            rate = _numbers(data, "rate_hz", src)
            if rate.size != 1:
                raise UserError(f"{src}: 'rate_hz' has shape {rate.shape}; accepted: one number")
            rate = float(rate.reshape(-1)[0])
        if rate is None and model_toml is not None:
            rate = _model(model_toml, src).rate_hz
        if rate is None:
            raise UserError(f"{src}: no 't' array and no sample rate; give --rate HZ")
        t = np.arange(n) / rate
    u, said = "m/s^2", "file"
    if unit is not None:
        u, said = parse_unit(unit), "--unit"
    elif "unit" in data:
        u = parse_unit(str(data["unit"][()]))
    elif default_unit is not None and default_unit != "counts":
        # an NPZ's accel is in m/s^2 unless it says otherwise: raw counts only when asked (--unit, 'unit')
        u, said = parse_unit(default_unit), "model"
    if UNITS[u] != 1.0:  # m/s^2 as stored: no copy of what may be gigabytes
        accel = accel * UNITS[u]
    idx = [_pick(a, names, names, src) for a in axes] if axes else list(range(k))
    if model_axes and len(set(names)) == k and {names[i] for i in idx} <= set(model_axes):  # by name
        idx.sort(key=lambda i: list(model_axes).index(names[i]))
    if idx != list(range(k)):
        accel = accel[:, idx]
        names = tuple(names[i] for i in idx)
        clipped = None if clipped is None else clipped[:, idx]
    rec = _finish(src, t, accel, names, names, (u,) * len(names), model_toml, clipped)
    tcol = "t" if "t" in data else None
    return replace(rec, time_column=tcol, time_unit=None if tcol else "s", unit_from=(said,) * len(names))


def no_input(src: str, keys) -> None:
    """Refuse an estimator's output written without its input (smooth's and filter's default: states, no
    acceleration), saying so, rather than as a recording that lacks a column (``keys``: its arrays, or its
    CSV columns past the axis name)."""
    if any(k.startswith(("smooth_", "filt_", "_smooth_", "_filt_")) for k in keys):
        raise UserError(
            f"{src}: an estimator's output without its input (positions and velocities, no acceleration): read the "
            "recording it was made from, or write the output with --full to keep the input in it"
        )


def _numbers(data: dict, key: str, src: str, dtype=np.float64) -> np.ndarray:
    """data[key] as an array of dtype; an array that is not numbers (strings, objects) is refused."""
    a = data[key]
    if a.dtype.kind not in "biuf":  # complex too: no acceleration or time is complex
        raise UserError(f"{src}: {key!r} holds {a.dtype} values; accepted: real numbers")
    return np.asarray(a, dtype=dtype)


def _model(text: str, src: str):
    try:
        return loads_model(text, source=f"{src}:model_toml")
    except ModelError as exc:
        raise UserError(f"the embedded model is not valid: {exc}") from None


def _pick(axis: str, names, cols, src: str) -> int:
    for i, (nm, col) in enumerate(zip(names, cols, strict=True)):
        if axis in (nm, col):
            return i
    raise UserError(f"{src}: no axis or column {axis!r}; available: {', '.join(cols)}")


def _open_text(path: Path, gz: bool):
    """The file as text in universal-newline mode (``\n``, ``\r\n`` and a lone ``\r`` all end a line)."""
    raw = gzip.open(path, "rb") if gz else open(path, "rb")
    return raw, io.TextIOWrapper(raw, encoding="utf-8-sig", newline=None)


def _blocks(path: Path, gz: bool, src: str):
    """(number of the first line, text of whole lines joined by newlines) per piece of about CHUNK_CHARS;
    memory is bounded by the piece, and a line longer than MAX_LINE_CHARS or a NUL byte (binary data) is
    refused where it is met. The text is not split into lines here: the reader's fast path never does."""
    kind = "gzip " if gz else ""
    try:
        raw, fh = _open_text(path, gz)
    except OSError as exc:
        raise UserError(f"{src}: cannot read: {exc.strerror or exc}") from None
    size = path.stat().st_size
    pos = raw.fileobj if gz else raw
    first, rest = 1, ""
    with fh, Progress("read", total=size, unit="bytes") as p:
        while True:
            try:
                block = fh.read(CHUNK_CHARS)
            except UnicodeDecodeError:
                raise UserError(f"{src}: not UTF-8 text (after line {first}); accepted: CSV, gzip CSV or NPZ") from None
            except (OSError, EOFError) as exc:
                raise UserError(f"{src}: cannot read as {kind}text: {excerpt(str(exc))}") from None
            text = rest + block
            nul = text.find("\0")
            if nul >= 0:
                raise UserError(
                    f"{src}: line {first + text.count(chr(10), 0, nul)} holds a NUL byte: binary data, not CSV text"
                )
            if block:
                cut = text.rfind("\n")
                text, rest = (text[:cut], text[cut + 1 :]) if cut >= 0 else ("", text)
                if len(rest) > MAX_LINE_CHARS:
                    n_lines = text.count("\n") + 1 if cut >= 0 else 0
                    raise UserError(
                        f"{src}: line {first + n_lines} is longer than {MAX_LINE_CHARS} characters "
                        f"({excerpt(rest)}); accepted: CSV text"
                    )
                if cut >= 0:
                    yield first, text
                    first += text.count("\n") + 1
            else:
                if text:
                    yield first, text
                return
            p.update(pos.tell())


def _fields_per_line(text: str, delim: str) -> np.ndarray:
    """Number of ``delim`` on each line of ``text``, from the positions of the newlines and delimiters
    (whole-array operations: a Python loop over the lines was most of the reader's time)."""
    b = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    ends = np.flatnonzero(b == 10)
    d = np.flatnonzero(b == ord(delim))
    bounds = np.searchsorted(d, np.concatenate(([-1], ends, [len(b)])))
    return np.diff(bounds)


def _read_csv(path: Path, axes, unit, rate_hz, time_column, gz: bool, default=None, model_axes=None) -> Recording:
    """Streamed: the text is parsed piece by piece, only the numbers (and each sample's line) are kept."""
    src = str(path)
    head = None
    pieces: list[np.ndarray] = []
    line_nos: list[np.ndarray] = []
    held = 0
    limit = input_limit()
    for h, table, nums in csv_pieces(path, axes, unit, rate_hz, time_column, gz, default, model_axes):
        head = h
        pieces.append(table)
        line_nos.append(nums)
        held += table.nbytes + nums.nbytes
        _check_held(held, limit, line_nos, src)
    table = np.concatenate(pieces) if pieces else np.empty((0, 0))
    data_lines = np.concatenate(line_nos) if line_nos else np.empty(0, np.int64)
    del pieces, line_nos
    if table.shape[0] < 2:
        raise UserError(f"{src}: {table.shape[0]} data rows; a recording needs many more")
    time_unit = csv_time_unit(head)
    t = csv_time(head, table, 0, rate_hz)
    with np.errstate(over="ignore"):  # a number beyond float64 once in m/s^2 becomes inf, refused by name below
        accel = csv_accel(head, table)
    rec = _finish(src, t, accel, tuple(head.names), tuple(head.chosen), tuple(head.units), None, None)
    return replace(rec, lines=data_lines, time_unit=time_unit, time_column=head.tcol, unit_from=head.unit_from)


def csv_time_unit(head: _Header) -> str:
    """The unit of the time column as its name says it (None: unsaid), "s" for time from the rate."""
    if head.tcol is None:
        return "s"
    return time_unit_of(head.tcol)


def csv_time(head: _Header, table: np.ndarray, first: int, rate_hz: float | None) -> np.ndarray:
    """Time [s, or the column's unsaid unit] of parsed rows ``first``.. of a CSV: its column, or from the rate."""
    if head.tcol is None:
        return np.arange(first, first + table.shape[0]) / rate_hz
    return table[:, 0] * TIME_SCALE[csv_time_unit(head)]


def csv_accel(head: _Header, table: np.ndarray) -> np.ndarray:
    """Acceleration [m/s^2, or raw counts] of parsed CSV rows, each column by its unit."""
    data = table[:, 1:] if head.tcol is not None else table
    return data * np.array([UNITS[u] for u in head.units])


def csv_pieces(path: Path, axes, unit, rate_hz, time_column, gz: bool, default=None, model_axes=None):
    """(header, numbers (rows, len(header.use)), their file lines) per piece of the CSV's text: the one
    parser of the format, for the whole-file reader and the streamed one (accelnav.data.stream).

    Once the header is known, and threads are asked for (:func:`accelnav.resources.threads`), the C parser
    reads up to PARSE_AHEAD pieces ahead on other threads (it releases the interpreter's lock), while this one reads the
    text and the caller takes the pieces, in order: the same numbers, the same refusals, in the same
    place."""
    src = str(path)
    lanes = threads()
    pool = ThreadPoolExecutor(lanes, thread_name_prefix="accelnav-csv") if lanes > 1 else None
    ahead: deque = deque()  # (first, text, the C parser's table in the making) of pieces after the header
    try:
        head = None
        for first, text in _blocks(path, gz, src):
            fast = head is not None and len(head.cols) > 1 and "#" not in text
            if pool is None or not fast:
                while ahead:  # the pieces before this one first, in order
                    yield from _piece(*ahead.popleft(), head, src)
                if fast:
                    # the C parser (accelnav.data.csvnum) first; what it does not read, numpy's paths read or refuse
                    yield from _piece(first, text, csvnum.piece(text, head.delim, len(head.cols), head.use), head, src)
                    continue
            else:
                ahead.append((first, text, pool.submit(csvnum.piece, text, head.delim, len(head.cols), head.use)))
                while len(ahead) > PARSE_AHEAD:
                    yield from _piece(*ahead.popleft(), head, src)
                continue
            for got in _lines_piece(first, text, head, src, axes, unit, rate_hz, time_column, default, model_axes):
                head = got[0]
                if got[1] is not None:
                    yield got
        while ahead:
            yield from _piece(*ahead.popleft(), head, src)
        if head is None:
            raise UserError(f"{src}: no header row (the file is empty)")
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)


def _piece(first: int, text: str, table, head: _Header, src: str):
    """A piece with the header's fields and no comment: the C parser's ``table`` (or its future), else numpy's
    paths; what none of them reads goes line by line (:func:`_lines_piece`), which says what is wrong."""
    if isinstance(table, Future):
        table = table.result()
    if table is None:
        table = _every_column(text, head)
    if table is not None:
        yield head, table, np.arange(first, first + len(table), dtype=np.int64)
        return
    # fast path: no comment, and every line has the header's delimiters (so none is blank)
    n_delims = _fields_per_line(text, head.delim)
    if np.all(n_delims == len(head.cols) - 1):
        nums = np.arange(first, first + len(n_delims), dtype=np.int64)
        yield head, _parse_piece(text, nums, head, src), nums
        return
    for got in _lines_piece(first, text, head, src):
        if got[1] is not None:
            yield got


def _lines_piece(first: int, text: str, head, src: str, *header_args):
    """A piece line by line (comments, blank lines, the header): (header, numbers, their lines) of its rows,
    else (header, None, None) once the header is known; ``header_args`` make the header (axes, unit,
    rate_hz, time_column, default, model_axes) where the piece holds it."""
    lines = text.split("\n")
    rows, nums = [], []
    for i, line in enumerate(lines):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if head is None:
            head = _header(line, first + i, src, *header_args)
            continue
        if line.count(head.delim) != len(head.cols) - 1:
            hint = ""
            if head.delim == "," and line.count(",") > len(head.cols) - 1:
                # "0,01188" between commas cannot be told from two fields
                hint = (
                    "; if the numbers have a decimal comma (0,01188), separate the fields with ';' "
                    "(read as decimal commas) or write decimal points"
                )
            raise UserError(
                f"{src}: line {first + i}: {line.count(head.delim) + 1} fields; the header has {len(head.cols)}{hint}"
            )
        rows.append(line)
        nums.append(first + i)
    if rows:
        nums = np.asarray(nums, dtype=np.int64)
        yield head, _parse_piece(rows, nums, head, src), nums
    elif head is not None:
        yield head, None, None


def _every_column(text: str, head: _Header) -> np.ndarray | None:
    """The numbers of a piece whose every column is wanted, when each of its lines is a row of the header's
    fields (None: let the line-checking paths find what is wrong, and say it). loadtxt refuses a row whose
    field count differs from the first's, and the shape catches a piece of blank lines or wrong counts
    throughout: no per-line Python and no count of delimiters (a fifth of the reader's time)."""
    if head.use != list(range(len(head.cols))):
        return None
    parsed = text.replace(",", ".") if head.delim != "," else text  # ';' or tab between fields: decimal commas
    try:
        table = np.loadtxt(io.StringIO(parsed), delimiter=head.delim, ndmin=2, dtype=np.float64, comments=None)
    except ValueError:
        return None
    return table if table.shape == (text.count("\n") + 1, len(head.cols)) else None


def _parse_piece(rows, nums, head, src: str) -> np.ndarray:
    """The numbers of ``rows`` (a list of lines, or whole lines as one text), (len(rows), len(head.use))."""
    text = rows if isinstance(rows, str) else None
    comma = head.delim != ","  # with ';' or tab between fields a comma can only be a decimal comma
    if comma:
        parsed = text.replace(",", ".") if text is not None else [r.replace(",", ".") for r in rows]
    else:
        parsed = text if text is not None else rows
    # every line has the header's fields by now: with every column wanted, usecols is only a cost
    use = None if head.use == list(range(len(head.cols))) else head.use
    try:
        chunk = np.loadtxt(
            io.StringIO(parsed) if text is not None else parsed,
            delimiter=head.delim,
            usecols=use,
            ndmin=2,
            dtype=np.float64,
            comments="#",
        )
    except ValueError:
        lines = text.split("\n") if text is not None else rows
        _locate_bad_cell(lines, nums, head.delim, head.cols, head.use, src, comma)
        raise  # _locate_bad_cell always raises; this keeps linters quiet
    return chunk.reshape(-1, len(head.use))


def _check_held(held: int, limit: int, line_nos: list, src: str) -> None:
    if held > limit:
        raise UserError(
            f"{src}: more than {sum(len(n) for n in line_nos)} samples by line {int(line_nos[-1][-1])}; accepted: "
            f"at most {limit >> 20} MiB of samples (ACCELNAV_MAX_INPUT_BYTES); cut the recording"
        )


@dataclass(frozen=True)
class _Header:
    delim: str
    cols: list[str]
    tcol: str | None
    chosen: list[str]
    units: list[str]
    names: list[str]
    use: list[int]
    unit_from: tuple[str, ...] = ()  # per axis: "name", "--unit" or "model" (what said the unit)


def _cols(cols) -> str:
    """The column names for a message, each and all of them capped."""
    text = ", ".join(c if len(c) <= 40 else c[:37] + "..." for c in cols)
    return text if len(text) <= 4 * EXCERPT_CHARS else text[: 4 * EXCERPT_CHARS - 3] + "..."


def _header(
    header: str, line_no: int, src: str, axes, unit, rate_hz, time_column, default=None, model_axes=None
) -> _Header:
    delim = max((",", ";", "\t"), key=header.count)
    if header.count(delim) == 0:
        delim = ","
    cols = [c.strip().strip('"').strip() for c in header.split(delim)]
    if any(_is_number(c) for c in cols):
        raise UserError(f"{src}: line {line_no} should be a header of column names, got {excerpt(header)}")
    if len(set(cols)) != len(cols):
        raise UserError(f"{src}: duplicate column names in the header: {_cols(cols)}")

    tcol, chosen, units, unit_from, names = _choose(cols, src, axes, unit, rate_hz, time_column, default, model_axes)
    # every data row must have the header's number of fields: an extra or a missing cell is refused
    # (loadtxt with usecols would drop an extra one silently); the line of each sample is kept for messages
    use = ([cols.index(tcol)] if tcol is not None else []) + [cols.index(c) for c in chosen]
    return _Header(delim, cols, tcol, chosen, units, names, use, unit_from)


def _choose(cols: list[str], src: str, axes, unit, rate_hz, time_column, default, model_axes):
    """(time column, acceleration columns, their units, where each unit came from, their axis names) by
    the column rules (accelnav.data.columns); the axes in the model's order when every one is a model axis."""
    if time_column is not None:
        if time_column not in cols:
            raise UserError(f"{src}: no time column {excerpt(time_column)}; columns: {_cols(cols)}")
        tcol = time_column
    else:
        tcol = pick_time(cols)
    if tcol is None and rate_hz is None:
        raise UserError(f"{src}: no time column (t, t_s, time, ...) and no --rate; columns: {_cols(cols)}")
    short = {c: axis_of(c, model_axes) for c in cols}
    if axes:
        chosen = []
        for a in axes:
            hits = [c for c in cols if a == c] or [c for c in cols if short[c] is not None and a == short[c]]
            if not hits:
                raise UserError(f"{src}: no column {excerpt(a)}; columns: {_cols(cols)}")
            chosen.append(hits[0])
    else:
        chosen = [c for c in cols if short[c] is not None and c != tcol]
        # accelnav's own CSVs hold an axis twice, as raw codes and in m/s^2: the acceleration is taken
        accel = {short[c] for c in chosen if unit_of(c) != "counts"}
        chosen = [c for c in chosen if unit_of(c) != "counts" or short[c] not in accel]
        if not chosen:
            no_input(src, [c[c.find("_") :] for c in cols])
            raise UserError(
                f"{src}: no acceleration column (acc_x_g, ax, x, Acceleration x (m/s^2), ...); name one with --axis; "
                f"columns: {_cols(cols)}"
            )
    flag = None if unit is None else parse_unit(unit)
    units, unit_from = [], []
    for c in chosen:
        said = unit_of(c)
        if flag is not None and said is not None and said != flag:
            raise UserError(
                f"{src}: --unit {unit} contradicts column {excerpt(c)}, whose name says {said}; drop --unit or "
                "rename the column"
            )
        if said is None and flag is None and default is None:
            raise UserError(
                f"{src}: column {excerpt(c)} does not say its unit (suffix _g, _mg, _m_s2, _counts); "
                "give --unit g, m/s^2 or counts"
            )
        # the name, else --unit, else the model's (a calibrated part's samples, an analog part's raw codes)
        units.append(said or flag or parse_unit(default))
        unit_from.append("name" if said else "--unit" if flag else "model")
    names = [short[c] or c for c in chosen]
    if len(set(names)) != len(names):
        names = list(chosen)
    elif model_axes and set(names) <= set(model_axes):  # matched by name, whatever the columns' order
        order = sorted(range(len(names)), key=lambda i: list(model_axes).index(names[i]))
        chosen, units, unit_from, names = ([x[i] for i in order] for x in (chosen, units, unit_from, names))
    return tcol, chosen, units, tuple(unit_from), names


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _locate_bad_cell(lines, nums, delim, cols, use, src, comma=False) -> None:
    for line, no in zip(lines, nums, strict=True):
        cells = line.split(delim)
        for j in use:
            cell = cells[j].strip() if j < len(cells) else ""
            if not _is_number(cell.replace(",", ".") if comma else cell):
                what = "is empty" if not cell else f"is not a number ({excerpt(cell, 24)})"
                raise UserError(
                    f"{src}: line {no}, column {excerpt(cols[j], 40)} {what}; a gap in the data is not accepted"
                )
    raise UserError(f"{src}: cannot parse the numbers (rows of unequal length?)")


def _finish(src, t, accel, names, cols, units, model_toml, clipped) -> Recording:
    return Recording(
        source=src,
        t=t,
        accel=np.ascontiguousarray(accel),
        axis_names=tuple(names),
        columns=tuple(cols),
        units=tuple(units),
        rate_hz=float("nan"),
        model_toml=model_toml,
        clipped=clipped,
    )


def from_arrays(source: str, arrays: dict[str, np.ndarray], axes: list[str] | None = None) -> Recording:
    """A recording from run-file arrays (t, axis_names, accel in m/s^2, clipped, model_toml), time checked."""
    names = tuple(str(a) for a in arrays["axis_names"])
    idx = [_pick(a, names, names, source) for a in axes] if axes else list(range(len(names)))
    rec = _finish(
        source,
        np.asarray(arrays["t"], dtype=np.float64),
        np.asarray(arrays["accel"], dtype=np.float64)[:, idx],
        tuple(names[i] for i in idx),
        tuple(names[i] for i in idx),
        ("m/s^2",) * len(idx),
        str(arrays["model_toml"]) if "model_toml" in arrays else None,
        np.asarray(arrays["clipped"], dtype=bool)[:, idx] if "clipped" in arrays else None,
    )
    return _check_time(replace(rec, time_unit="s", time_column="t"), None, False)


def _with_time_unit(rec: Recording, time_unit: str | None, where) -> Recording:
    """``rec`` with its time column in seconds by --time-unit, where the column's name does not say its unit."""
    if time_unit is None:
        return rec
    if rec.time_column is None:
        raise UserError(f"--time-unit: {where} has no time column (its time comes from the rate)")
    if rec.time_unit not in (None, time_unit):
        raise UserError(
            f"--time-unit {time_unit}: the time column {rec.time_column!r} says its unit is {rec.time_unit}"
        )
    if rec.time_unit is None:
        rec = replace(rec, t=rec.t * TIME_SCALE[time_unit], time_unit=time_unit)
    return rec


def _check_time(rec: Recording, rate_given: float | None, allow_gaps: bool) -> Recording:
    """Finite, increasing time; the rate and the samples' places on its grid; gaps refused unless allowed.

    A regular clock (every step within GAP_FACTOR of the median) keeps its stamps and its mean rate. Any
    other clock is placed on a nominal grid t0 + k / f: f is ``rate_given``, else the first of the mean
    regular step, the median step and the mean over the run (the last two rounded to whole Hz within
    SNAP_TOL) on whose grid the stamps fit, each within half a period of its own grid point (gaps: the
    points between are missing), or failing that, stamps that jitter by more (bunched by a USB or OS
    buffer) but stay within MAX_LAG_PERIODS of their order, sample i at t0 + i / f. What fits neither
    is refused, saying how to resample. ``rate_given`` with a time column is checked against it the same
    way; if the stamps do not fit it, it overrides them (samples taken as consecutive), said in a note.
    """
    src, t = rec.source, rec.t
    if not np.isfinite(t).all():
        k = int(np.argmax(~np.isfinite(t)))
        raise UserError(f"{src}: time is not a finite number at {rec.where(k)}")
    dt = np.diff(t)
    back = dt <= 0
    if back.any():
        k = int(np.argmax(back))
        raise UserError(
            f"{src}: time does not increase at {rec.where(k + 1)} (t = {t[k]:.6g} s, then {t[k + 1]:.6g} s); "
            f"{int(back.sum())} such steps"
        )
    step = float(np.median(dt))
    clock = rec.time_column
    if clock is None:  # the time came from the rate: a perfect grid
        return replace(rec, rate_hz=(len(t) - 1) / float(t[-1] - t[0]))
    if rec.time_unit is None:
        unit, said = epoch_unit(src, clock, float(t[0]), step)
        if unit is not None:
            scale = TIME_SCALE[unit]
            rec = replace(rec, t=t * scale, time_unit=unit, notes=rec.notes + (said,))
            t, dt, step = rec.t, dt * scale, step * scale
    if rec.time_unit is None and 1.0 / step < MIN_CLOCK_HZ:
        raise UserError(
            f"{src}: the time column {clock!r} steps by {step:.6g} (median): read as seconds that is "
            f"{1.0 / step:.6g} Hz, too slow for an accelerometer; it looks like milliseconds: give --time-unit ms "
            "(or name the column t_ms), or convert it to seconds"
        )
    regular = bool(np.all(dt <= GAP_FACTOR * step) and np.all(dt >= step / GAP_FACTOR))
    if regular and rate_given is None:
        return replace(rec, rate_hz=(len(t) - 1) / float(t[-1] - t[0]))  # the mean step: less rounding
    gap = dt > GAP_FACTOR * step
    if rate_given is not None:
        candidates = [rate_given]
    else:
        reg = dt[~gap & (dt >= step / GAP_FACTOR)]
        candidates = [1.0 / float(np.mean(reg))] if len(reg) else []
        candidates += [_snap(1.0 / step), _snap((len(t) - 1) / float(t[-1] - t[0]))]
    span = f"steps {1e3 * dt.min():.3g} to {1e3 * dt.max():.3g} ms, median {1e3 * step:.4g} ms"
    # each candidate's placement, by stamp or else by order; the one that leaves the fewest samples missing
    # wins (a median step from bunched stamps is tiny, and its grid fits them with almost every point empty)
    placements = [p for p in (_grid_place(t, f) or _order_place(t, f) for f in candidates) if p is not None]
    placed = min(placements, key=lambda p: int(p[0][-1]) + 1 - len(t), default=None)
    if placed is None:
        if rate_given is not None:
            note = (
                f"{src}: --rate {rate_given:g} Hz overrides the time column {clock!r} ({span}; its stamps do not fit "
                f"a {rate_given:g} Hz grid): the samples are taken as consecutive at {rate_given:g} Hz"
            )
            t_new = t[0] + np.arange(len(t)) / rate_given
            return replace(rec, t=t_new, rate_hz=float(rate_given), notes=rec.notes + (note,))
        raise UserError(
            f"{src}: the time column {clock!r} fits no fixed sample rate ({span}; tried "
            f"{', '.join(f'{f:.6g}' for f in candidates)} Hz): resample the recording onto a uniform grid, or give "
            "--rate HZ to take the samples as consecutive at HZ"
        )
    k, f, how = placed
    jumps = np.diff(k) > 1
    if jumps.any() and not allow_gaps:
        i = int(np.argmax(jumps))
        raise UserError(
            f"{src}: gap in time of {dt[i]:.6g} s at t = {t[i]:.6g} s (after {rec.where(i)}; the usual step is "
            f"{step:.6g} s); {int(jumps.sum())} gaps in all"
        )
    notes = rec.notes
    if rate_given is not None:
        notes += (f"{src}: --rate {rate_given:g} Hz checked against the time column {clock!r}: it fits",)
    if np.any(dt < step / GAP_FACTOR) or how.startswith("by their order"):
        off = t - t[0] - k / f
        notes += (
            f"{src}: the clock {clock!r} jitters ({span}, {1e3 * float(np.sqrt(np.mean(off**2))):.3g} ms rms off the "
            f"grid): samples placed on the {f:.6g} Hz grid {how}",
        )
    if regular and not jumps.any():  # a regular clock the rate agrees with: its stamps as they are
        return replace(rec, rate_hz=(len(t) - 1) / float(t[-1] - t[0]), notes=notes)
    return replace(rec, t=t[0] + k / f, rate_hz=float(f), notes=notes)


def _order_place(t: np.ndarray, f: float):
    """(k, f, how) with sample i at t0 + i / f when no stamp lags its order by MAX_LAG_PERIODS; else None."""
    lag = (t - t[0]) * f - np.arange(len(t))
    if np.ptp(lag) > MAX_LAG_PERIODS:
        return None
    return np.arange(len(t)), f, f"by their order (the stamps within {1e3 * float(np.ptp(lag)) / f:.3g} ms of it)"


def _snap(f: float) -> float:
    """``f`` rounded to whole Hz when within SNAP_TOL of it (from 10 Hz up), else ``f``."""
    r = float(round(f))
    return r if f >= 10 and abs(f / r - 1) <= SNAP_TOL else f


def _grid_place(t: np.ndarray, f: float):
    """(k, f, how) when every stamp is within half a period of its point t0 + k / f, k increasing; else None."""
    pos = np.rint((t - t[0]) * f)
    if not np.all(np.abs(pos) < 2.0**62):  # a span no sample index reaches: no grid (and no int64 overflow)
        return None
    k = pos.astype(np.int64)
    off = np.abs(t - t[0] - k / f)
    if np.any(off >= 0.5 / f) or np.any(np.diff(k) < 1):
        return None
    return k, f, f"by time stamp (each within {1e3 * float(off.max()):.3g} ms of its point)"


def check_rate(rec: Recording, model_rate_hz: float, model_source: str) -> None:
    """Refuse a recording whose sample rate is not the model's, in one line (naming a millisecond clock)."""
    check_step(rec.source, float(np.median(np.diff(rec.t))), rec.time_unit, model_rate_hz, model_source)


def check_step(source: str, step: float, time_unit: str | None, model_rate_hz: float, model_source: str) -> None:
    """:func:`check_rate` from the median step [s] (a streamed input has no whole time array)."""
    rate = 1.0 / step
    if abs(rate / model_rate_hz - 1) <= 0.01:
        return
    if time_unit is None and abs(rate * 1000.0 / model_rate_hz - 1) <= 0.01:
        raise UserError(
            f"{source}: the time column looks like milliseconds (median step {step:.6g}, the model's "
            f"{model_rate_hz:g} Hz is a step of {1000.0 / model_rate_hz:.6g} ms); name it t_ms or give seconds"
        )
    raise UserError(
        f"{source}: the recording is sampled at {rate:.6g} Hz (median step {step:.6g} s) but the model "
        f"{model_source} has sampling.rate_hz = {model_rate_hz:g} Hz; use a model made for {rate:.6g} Hz"
    )


def on_grid(
    rec: Recording, rate_hz: float, max_samples: int, limit: str = "the model's ranges.max_run_s allows"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, accel, missing): the samples placed on the uniform grid t0 + k / rate_hz, gaps filled with NaN.

    Each sample must lie within a quarter period of its grid point (the
    recording's timing jitter, checked whether or not there are gaps); a filled
    run longer than ``max_samples`` samples in all is refused (memory bound), the line saying ``limit``
    before the number.
    """
    Ts = 1.0 / rate_hz
    k = np.rint((rec.t - rec.t[0]) / Ts).astype(np.int64)
    off = np.abs(rec.t - rec.t[0] - k * Ts) > 0.25 * Ts
    if off.any():
        i = int(np.argmax(off))
        raise UserError(
            f"{rec.source}: {rec.where(i)} (t = {rec.t[i]:.6g} s) is off the {rate_hz:.6g} Hz sample grid by more "
            "than a quarter period: the timing jitters too much for a fixed-rate filter"
        )
    if np.any(np.diff(k) < 1):
        i = int(np.argmax(np.diff(k) < 1)) + 1
        raise UserError(f"{rec.source}: {rec.where(i)} falls on the same sample period as the one before it")
    n = int(k[-1]) + 1
    if n > max_samples:
        raise UserError(f"{rec.source}: with its gaps filled the recording is {n} samples; {limit} {max_samples}")
    t = rec.t[0] + np.arange(n) * Ts
    if n == len(k):  # no gap (k strictly increasing from 0): every sample is its own grid point, nothing to fill
        return t, np.array(rec.accel, dtype=np.float64), np.zeros(n, dtype=bool)
    accel = np.full((n, rec.accel.shape[1]), np.nan)
    accel[k] = rec.accel
    missing = np.ones(n, dtype=bool)
    missing[k] = False
    return t, accel, missing


def check_axis(
    rec: Recording,
    axis: str,
    *,
    min_duration_s: float = MIN_DURATION_S,
    min_samples: int = MIN_SAMPLES,
    full_scale: float | None = None,
    sensor_range: tuple[float, str] | None = None,
    step: float = 0.0,
) -> np.ndarray:
    """The samples of ``axis`` if the bias fit can use them; otherwise a UserError saying what and where.

    ``sensor_range``: (largest |a| in m/s^2, whose range it is); a sample beyond it is a glitch or a wrong
    unit, named by its place, rather than left to wreck the fit. ``step``: the read-out step the samples
    are quantised to [m/s^2] (0: none known). Where the noise is below one step, one or two codes hold most
    samples wherever the rails are, so a pile at the data's own extreme is no evidence of clipping: only
    the rails (flagged samples, the full scale) decide then."""
    j = rec.column(axis)
    y = rec.accel[:, j]
    where = f"{rec.source}: axis {rec.axis_names[j]!r}"
    bad = ~np.isfinite(y)
    if bad.any():
        k = int(np.argmax(bad))
        raise UserError(
            f"{where}: {int(bad.sum())} samples are not numbers (NaN/inf), the first at sample {k} "
            f"(t = {rec.t[k]:.6g} s); gaps in the data are not accepted"
        )
    # a code at the ADC's rails is named as clipped before its value is judged against the range
    if rec.clipped is not None and rec.clipped[:, j].any():
        c = rec.clipped[:, j]
        k = int(np.argmax(c))
        raise UserError(
            f"{where}: {int(c.sum())} samples are flagged clipped, the first at sample {k} (t = {rec.t[k]:.6g} s)"
        )
    if sensor_range is not None:
        out = np.abs(y) > sensor_range[0]
        if out.any():
            k = int(np.argmax(out))
            raise UserError(
                f"{where}: {rec.where(k)}, column {excerpt(rec.columns[j], 40)}: {y[k]:.6g} m/s^2 is beyond the "
                f"range +-{sensor_range[0]:.6g} m/s^2 of "
                f"{sensor_range[1]} ({int(out.sum())} such samples): a glitch, or the wrong unit"
            )
    if rec.duration < min_duration_s or rec.n < min_samples:
        raise UserError(
            f"{where}: too short: {rec.duration:.4g} s, {rec.n} samples; identifying the warm-up time constant T "
            f"needs at least {min_duration_s:g} s and {min_samples} samples"
        )
    lo, hi = float(y.min()), float(y.max())
    if lo == hi:
        raise UserError(f"{where}: the signal is constant ({lo:.6g} m/s^2 in every sample); a sensor that is not alive")
    if full_scale is not None:
        at_rail = np.abs(y) >= full_scale * (1 - 1e-6)
        if at_rail.any():
            k = int(np.argmax(at_rail))
            raise UserError(
                f"{where}: {int(at_rail.sum())} samples at the sensor's full scale +-{full_scale:.6g} m/s^2, "
                f"the first at sample {k} (t = {rec.t[k]:.6g} s): the signal is clipped"
            )
    values, counts = np.unique(y, return_counts=True)
    coarse = step > 0 and np.std(np.diff(y)) / np.sqrt(2) < step  # short-term spread under one step
    if len(values) >= 3 and not coarse:
        for end, inner, label in ((-1, -2, "maximum"), (0, 1, "minimum")):
            if counts[end] >= PILEUP_FRACTION * len(y) and counts[end] > counts[inner]:
                k = int(np.argmax(y == values[end]))
                raise UserError(
                    f"{where}: {counts[end]} samples ({100 * counts[end] / len(y):.2g} %) sit at the {label} "
                    f"{values[end]:.6g} m/s^2, more than at the next value: the signal is clipped there "
                    f"(first at sample {k}, t = {rec.t[k]:.6g} s)"
                )
    return y


def from_columns(
    source: str,
    columns: dict[str, np.ndarray],
    *,
    axes: list[str] | None = None,
    unit: str | None = None,
    rate_hz: float | None = None,
    time_column: str | None = None,
    allow_gaps: bool = False,
    time_unit: str | None = None,
    default_unit: str | None = None,
    model_axes: list[str] | None = None,
) -> Recording:
    """A recording from named columns held in memory (numpy arrays, a DataFrame's columns).

    The columns are read as a CSV with that header would be: the same names pick the time and the
    acceleration columns and say their units, and the same clock, rate and gap checks follow. A datetime64
    or timedelta64 column is read as seconds (the clock when no column is named as time).
    """
    names = [str(c) for c in columns]
    bad = [c for c in names if any(d in c for d in ",;\t\n")]
    if bad:
        raise UserError(f"{source}: column name {excerpt(bad[0])} holds a separator; rename it")
    if rate_hz is not None and not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise UserError(f"--rate: got {rate_hz}; accepted: a positive sample rate in Hz")
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise UserError(f"--time-unit: got {time_unit!r}; accepted: {', '.join(TIME_UNITS)}")
    arrays = dict(zip(names, columns.values(), strict=True))
    typed = [c for c in names if np.asarray(arrays[c]).dtype.kind in "Mm"]  # datetime64, timedelta64
    if time_column is None and typed and pick_time(names) is None:
        time_column = typed[0]  # no column is named as time, one holds times: it is the clock
    head = _header(",".join(names), 1, source, axes, unit, rate_hz, time_column, default_unit, model_axes)
    table, notes = [], ()
    for j in head.use:
        raw = np.asarray(arrays[head.cols[j]]).reshape(-1)
        if raw.dtype.kind in "Mm":
            if head.cols[j] != head.tcol:
                raise UserError(f"{source}: column {excerpt(head.cols[j])} holds {raw.dtype} values, not acceleration")
            col, said = _seconds(raw)
            if time_unit is not None:
                raise UserError(f"--time-unit {time_unit}: the time column {head.tcol!r} is {raw.dtype}, which says it")
            notes += (f"{source}: time column {head.tcol!r} read from its {raw.dtype} values {said}",)
            table.append(col)
            continue
        try:
            col = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError):
            raise UserError(f"{source}: column {excerpt(head.cols[j])} is not numbers") from None
        table.append(col)
    if len({len(c) for c in table}) != 1:
        raise UserError(f"{source}: columns of unequal length: {', '.join(str(len(c)) for c in table)}")
    table = np.column_stack(table)
    if table.shape[0] < 2:
        raise UserError(f"{source}: {table.shape[0]} samples; a recording needs many more")
    if head.tcol is not None:
        tu = "s" if notes else time_unit_of(head.tcol)
        t, data = table[:, 0] * TIME_SCALE[tu], table[:, 1:]
    else:
        t, data, tu = np.arange(table.shape[0]) / rate_hz, table, "s"
    accel = data * np.array([UNITS[u] for u in head.units])
    rec = _finish(source, t, accel, tuple(head.names), tuple(head.chosen), tuple(head.units), None, None)
    rec = replace(rec, time_unit=tu, time_column=head.tcol, unit_from=head.unit_from, notes=notes)
    return _check_time(_with_time_unit(rec, time_unit, source), rate_hz, allow_gaps)


def _seconds(raw: np.ndarray) -> tuple[np.ndarray, str]:
    """Seconds of datetime64 (since the epoch) or timedelta64 values, NaT as NaN; and how, for a note."""
    ns = raw.astype("datetime64[ns]" if raw.dtype.kind == "M" else "timedelta64[ns]")
    sec = ns.view(np.int64).astype(np.float64) * 1e-9
    sec[np.isnat(ns)] = np.nan
    if raw.dtype.kind == "m":
        return sec, "as seconds"
    first = str(ns[~np.isnat(ns)][0]) if (~np.isnat(ns)).any() else "NaT"
    return sec, f"as seconds since 1970-01-01 UTC (first {first[:23]})"


def in_accel(rec: Recording, model) -> Recording:
    """``rec`` with its raw columns (unit "counts") turned into m/s^2 by the model's own read-out.

    The conversion is :func:`accelnav.model.design.input_conversion`, the arithmetic the generated C and
    the simulator use, with each axis's calibration (zero-g, sensitivity, as ``calibrate`` wrote them). A
    column maps to the model axis of its name, else to the axis at its place. Codes at the ADC's rails
    are flagged as clipped, as the firmware skips them. Columns already in g or m/s^2 pass unchanged.
    """
    raw = [u == "counts" for u in rec.units]
    if not any(raw):
        return rec
    if not all(raw):
        raise UserError(f"{rec.source}: raw counts mixed with columns in g or m/s^2; give every axis in one unit")
    from accelnav.model.design import input_conversion

    names = [a.name for a in model.axes]
    if model.sensor.kind == "duty_cycle":
        raise UserError(
            f"{rec.source}: counts: {model.source} is a duty-cycle part, whose raw sample is a (T1, T2) pair, "
            "not one count per axis; give the acceleration in g or m/s^2"
        )
    if model.sensor.kind == "calibrated" and model.sensor.calibrated.lsb_per_g <= 0:
        raise UserError(f"{rec.source}: counts: {model.source} gives no sensor.calibrated.lsb_per_g to scale them")
    accel = np.empty_like(rec.accel)
    clipped = np.zeros(rec.accel.shape, dtype=bool) if rec.clipped is None else rec.clipped.copy()
    for j, name in enumerate(rec.axis_names):
        axis = name if name in names else j
        if isinstance(axis, int) and axis >= len(names):
            raise UserError(
                f"{rec.source}: counts column {rec.columns[j]!r} has no axis in {model.source} (axes "
                f"{', '.join(names)}) to convert it; give the part's own model with --model"
            )
        codes = rec.accel[:, j]
        if model.sensor.kind == "calibrated":
            accel[:, j] = codes / model.sensor.calibrated.lsb_per_g * G0
            continue
        conv = input_conversion(model, axis)
        finite = np.isfinite(codes)
        bad = finite & ((codes < 0) | (codes > conv.full_code) | (codes != np.round(codes)))
        if bad.any():
            k = int(np.argmax(bad))
            raise UserError(
                f"{rec.source}: {rec.where(k)}: {rec.columns[j]} = {codes[k]:g} is not an ADC code of "
                f"{model.source} (whole numbers 0..{conv.full_code})"
            )
        accel[:, j] = conv.accel(codes)
        clipped[:, j] |= conv.clipped(np.where(finite, codes, 1))
    units = tuple("m/s^2" for _ in rec.units)
    said = (f"{rec.source}: columns {', '.join(rec.columns)} read as raw ADC codes of {model.source} "
            "(converted by its read-out and calibration; give --unit g or m/s^2 if they are not codes)")  # fmt: skip
    return replace(rec, accel=accel, clipped=clipped, units=units, notes=rec.notes + (said,))


# the units a column may be read in, for the evidence (raw counts go through the model's read-out instead)
_ALT_UNITS = ("g", "mg", "m/s^2")
_SUFFIX = {"g": "_g", "mg": "_mg", "m/s^2": "_m_s2"}
LEVEL_TOL = 0.1  # a mean within 10 % of 9.80665 in a column read as g: a gravity in m/s^2


def unit_evidence(accel: np.ndarray, units, full_scale: float | None) -> np.ndarray:
    """What the data say of their units, to add up over blocks: per axis the sum of the samples [m/s^2], the
    finite samples, and how many lie beyond ``full_scale`` [m/s^2] (by BEYOND) read in each of _ALT_UNITS."""
    out = np.zeros((accel.shape[1], 2 + len(_ALT_UNITS)))
    for j, u in enumerate(units):
        a = accel[:, j][np.isfinite(accel[:, j])]
        out[j, :2] = float(a.sum()), len(a)
        if u in _ALT_UNITS and full_scale is not None:
            mag = np.abs(a)
            for k, alt in enumerate(_ALT_UNITS):  # the same numbers in alt: a * UNITS[alt] / UNITS[u]
                out[j, 2 + k] = np.count_nonzero(mag * (UNITS[alt] / UNITS[u]) > BEYOND * full_scale)
    return out


def unit_ratios(units, full_scale: float | None) -> tuple[np.ndarray, float]:
    """:func:`unit_evidence`'s counts as factors: (ratio (n_axes, len(_ALT_UNITS)), thr), a sample a of axis j
    counted for unit k when |a| * ratio[j, k] > thr; ratio 0 where unit_evidence counts nothing (thr > 0)."""
    ratio = np.zeros((len(units), len(_ALT_UNITS)))
    for j, u in enumerate(units):
        if u in _ALT_UNITS and full_scale is not None:
            ratio[j] = [UNITS[alt] / UNITS[u] for alt in _ALT_UNITS]
    return ratio, BEYOND * full_scale if full_scale is not None else np.inf


def evidence_of(accel: np.ndarray, beyond: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """:func:`unit_evidence` of a block with every sample finite, its counts ``beyond`` made already by
    :func:`unit_ratios`' rule (``ratio``): the same numbers (the sums of the same contiguous columns)."""
    out = np.zeros((accel.shape[1], 2 + len(_ALT_UNITS)))
    for j in range(accel.shape[1]):
        out[j, :2] = float(np.ascontiguousarray(accel[:, j]).sum()), len(accel)
    out[:, 2:] = np.where(ratio > 0, beyond, 0)
    return out


def check_units(src: str, columns, units, unit_from, evidence: np.ndarray, full_scale: float | None, whose: str):
    """Refuse, naming the unit it most likely has, a column whose unit no name said (--unit or the model's) when
    its data make that unit implausible: a share RAIL_SHARE of its samples past the sensor's range where
    another unit leaves under 1 % there, or a mean of about 9.8 read as g (a gravity in m/s^2). The data stay
    out when they cannot tell (a level trace read in either unit, a few samples clipped)."""
    for j, (col, u, said) in enumerate(zip(columns, units, unit_from, strict=True)):
        total, n = evidence[j, :2]
        if said == "name" or u not in _ALT_UNITS or n == 0:
            continue
        how = "--unit" if said == "--unit" else f"the unit of {whose}" if said == "model" else "the file's unit"
        mean = total / n / UNITS[u]  # in the claimed unit
        if full_scale is not None:
            share = evidence[j, 2 + _ALT_UNITS.index(u)] / n
            fits = [a for k, a in enumerate(_ALT_UNITS) if a != u and evidence[j, 2 + k] / n < 0.01]
            if share >= RAIL_SHARE and fits:
                alt = min(fits, key=lambda a: abs(np.log(UNITS[a] / UNITS[u])))  # the nearest unit that fits
                raise UserError(
                    f"{src}: column {excerpt(col, 40)} read in {u} ({how}) puts {100 * share:.0f} % of its samples "
                    f"beyond the sensor's range +-{full_scale / UNITS[u]:.4g} {u} ({whose}); in {alt} none of "
                    f"them would be: it is most likely in {alt}: give --unit {alt} or name it ..{_SUFFIX[alt]}"
                )
        if u == "g" and abs(abs(mean) - G0) <= LEVEL_TOL * G0:
            raise UserError(
                f"{src}: column {excerpt(col, 40)} read in g ({how}) holds {mean:.4g} g on average, a "
                f"{abs(mean) * G0:.3g} m/s^2 push no still or moving sensor keeps; as m/s^2 it is 1 g of gravity: "
                f"it is most likely in m/s^2: give --unit m/s^2 or name it .._m_s2"
            )


def check_rec_units(rec: Recording, full_scale: float | None, whose: str) -> None:
    """:func:`check_units` of a whole recording in memory."""
    if any(f != "name" for f in rec.unit_from):  # names said every unit: nothing to weigh (nor to cost)
        ev = unit_evidence(rec.accel, rec.units, full_scale)
        check_units(rec.source, rec.columns, rec.units, rec.unit_from, ev, full_scale, whose)
