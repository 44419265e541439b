"""A CSV recording of any length, checked as read_input checks it, in bounded memory.

:func:`read_input` holds the whole recording in arrays (about 70 bytes per sample, more while it
parses), so a 1e8-row CSV cannot go through it. :func:`open_stream` instead parses the CSV once with
the same parser (:func:`accelnav.data.recording.csv_pieces`: one CSV dialect for both) into a binary
store of its numbers and their file lines (none while every line is a row: line = first + row) in a
temporary folder, makes read_input's checks over that
store block by block (time finite and increasing, the clock's median step and regularity, the rate
against the model, the axes, counts converted by the model's read-out, NaN, each sample on the grid),
and returns a :class:`Stream`: the number of rows and ``read(s, e) -> (t, accel, clipped)`` for
:func:`accelnav.estimate.chunked.smooth_bounded`. Rows come back with the very numbers read_input
gives. The store is re-read rather than the text re-parsed: parsing is most of the cost, and the
store is a few times smaller than the text is to scan.

What needs the whole time array at once (a clock placed on a grid by :func:`_check_time`: jitter,
--rate with a time column, gaps filled in) raises :class:`NotStreamed`; the caller reads such an
input whole, where it fits.
"""

from __future__ import annotations

import errno
import os
import shutil
import stat
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from accelnav.data import recording as rc
from accelnav.data.csvnum import grid_block, time_block
from accelnav.errors import UserError
from accelnav.fileio import TempFolder, check_input, pread_exact
from accelnav.model.load import Model, load_model
from accelnav.progress import note

BLOCK = 1 << 20  # rows per block of the check passes and the largest read: the pass's memory
SAMPLE = 1 << 16  # bytes read at the start, middle and end of a CSV to estimate its rows
MAX_STEPS = 1 << 20  # distinct time steps counted for the exact median; a clock with more is read whole


class NotStreamed(UserError):
    """The input is valid as far as read, but only the whole-array reader handles it (the reason, one line)."""


@dataclass
class Stream:
    """A checked recording on disk: ``n`` rows of ``model``'s axes; call it as ``read(s, e)``.

    Use as a context manager: closing removes the store."""

    source: str
    n: int
    model: Model
    axis_names: np.ndarray
    head: object  # recording._Header
    folder: Path
    rate_hz: float | None  # --rate (time from the rate)
    time_unit: str | None  # --time-unit applied to an unsaid time column
    t0: float = 0.0
    Ts: float = 0.0
    _fds: dict = field(default_factory=dict)
    _scratch: TempFolder | None = None  # the store's folder (fileio.TempFolder: removed on close)
    kind: str = "CSV"
    # row k is on file line first_line + k (every line after the header a data line): no lines store kept
    first_line: int | None = None

    @property
    def width(self) -> int:
        return len(self.head.use)

    def rows(self, s: int, e: int, lines: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """(numbers (e-s, width), file lines (e-s,) or None without ``lines``) of rows s..e as parsed."""
        table = np.empty((e - s, self.width))
        nums = np.empty(e - s, dtype=np.int64) if lines else None
        if e > s:
            pread_exact(self._fds["store"], table, 8 * self.width * s, "input store", UserError)
            if lines and self.first_line is not None:
                nums[:] = self.first_line + np.arange(s, e)
            elif lines:
                pread_exact(self._fds["lines"], nums, 8 * s, "input store", UserError)
        return table, nums

    def raw_time(self, table: np.ndarray, s: int) -> np.ndarray:
        """Time of rows s.. in seconds, as read_recording makes it (column or rate, then --time-unit)."""
        return self._unit_time(rc.csv_time(self.head, table, s, self.rate_hz))

    def _unit_time(self, t: np.ndarray) -> np.ndarray:
        """Time read in the column's own unit, in seconds by --time-unit (or the unit its numbers said)."""
        if self.time_unit is not None and self.head.tcol is not None and rc.csv_time_unit(self.head) is None:
            t = t * rc.TIME_SCALE[self.time_unit]
        return t

    def times(self, s: int, e: int) -> np.ndarray:
        """:meth:`raw_time` of rows s..e (what the clock's pass reads)."""
        return self.raw_time(self.rows(s, e, lines=False)[0], s)

    def block(self, s: int, e: int, lines: bool = True) -> rc.Recording:
        """Rows s..e as a Recording in m/s^2 on the model (counts converted), its messages placed in the file
        (without ``lines``: by sample only, for rows checked already)."""
        table, lines = self.rows(s, e, lines)
        with np.errstate(over="ignore"):  # beyond float64 in m/s^2: inf, refused by name as not a number
            accel = rc.csv_accel(self.head, table)
        h = self.head
        rec = rc.Recording(
            source=self.source, t=self.raw_time(table, s), accel=np.ascontiguousarray(accel),
            axis_names=tuple(h.names), columns=tuple(h.chosen), units=tuple(h.units), rate_hz=float("nan"),
            lines=lines, first=s,
        )  # fmt: skip
        return rc.in_accel(rec, self.model)

    def __call__(self, s: int, e: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t on the grid, accel [m/s^2], clipped) of rows s..e, as read_input's run holds them."""
        rec = self.block(s, e, lines=False)  # checked by open_stream: no message will need a line
        t = self.t0 + np.arange(s, e) * self.Ts
        with np.errstate(invalid="ignore"):
            clipped = np.abs(rec.accel) >= self.model.max_accel_m_s2 * (1 - 1e-9)
        if rec.clipped is not None:
            clipped |= rec.clipped
        return t, rec.accel, clipped

    def close(self) -> None:
        for fd in self._fds.values():
            os.close(fd)
        self._fds.clear()
        if self._scratch is not None:
            self._scratch.close()

    def __enter__(self) -> Stream:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def estimate_rows(path: str | os.PathLike[str]) -> int | None:
    """Rows of a plain CSV estimated from its size and its first lines (None: not a plain CSV), read
    before anything is parsed: what decides whether the input is streamed."""
    path = Path(path)
    try:
        info = path.stat()
        if not stat.S_ISREG(info.st_mode):  # a FIFO or a device: a read could block or never end
            return None
        size = info.st_size
        with open(path, "rb") as fh:
            head = fh.read(SAMPLE)
            # lines grow along a file (its time stamps get longer): sample its middle and end as well
            parts = [head]
            for at in (size // 2, size - SAMPLE):
                if at > SAMPLE:
                    fh.seek(at)
                    parts.append(fh.read(SAMPLE))
    except OSError:
        return None
    if head[:2] == b"\x1f\x8b":
        return _gzip_rows(path, size)
    if head[:2] == b"PK" or b"\0" in head:
        return None
    lines = sum(p.count(b"\n") + p.count(b"\r") - p.count(b"\r\n") for p in parts)
    if lines == 0:
        return 0
    return int(size * lines / sum(map(len, parts)))


def _gzip_rows(path: Path, size: int) -> int | None:
    """Rows of a gzip CSV estimated from its first compressed bytes: their text's lines per byte times the
    compression ratio so far times the file's size (a recording compresses about evenly along its length)."""
    import zlib

    d = zlib.decompressobj(31)
    text, used = b"", 0
    try:
        with open(path, "rb") as fh:
            while len(text) < 4 * SAMPLE:
                piece = fh.read(SAMPLE // 4)
                if not piece:
                    break
                text += d.decompress(piece)
                used += len(piece) - len(d.unused_data)
                if d.eof:
                    break
    except (OSError, zlib.error):
        return None
    if b"\0" in text[:SAMPLE] or not used:
        return None
    lines = text.count(b"\n") + text.count(b"\r") - text.count(b"\r\n")
    if not text:
        return 0
    return int(size * (len(text) / used) * lines / len(text))


def open_stream(
    path: str | os.PathLike[str],
    model: Model | str | os.PathLike[str] | None = None,
    *,
    axes: list[str] | None = None,
    time_column: str | None = None,
    rate_hz: float | None = None,
    time_unit: str | None = None,
    unit: str | None = None,
    allow_gaps: bool = False,
    workdir: str | os.PathLike[str] | None = None,
    block: int = BLOCK,
) -> Stream:
    """A CSV or gzip CSV recording parsed into a store in ``workdir`` (default: the temporary folder) and
    checked as :func:`accelnav.data.inputs.read_input` checks it; the keywords are its own. Refusals
    are UserError in one line (the same as read_input's); NotStreamed when only the whole reader can
    take it. ``allow_gaps`` is accepted for the same signature; a gap refuses or goes to the whole
    reader, as it would there. Close the result (or use it in a ``with``) to remove the store."""
    from accelnav.data.imu import sniff
    from accelnav.data.inputs import _unit, model_axes, target_axes
    from accelnav.link.logfile import is_log

    override = model if isinstance(model, Model) or model is None else load_model(model)
    if sniff(path):  # its columns are the body frame's: only the whole reader levels them
        raise NotStreamed(f"{path}: an IMU log is levelled whole")
    path = check_input(path)
    src = str(path)
    if rate_hz is not None and not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise UserError(f"--rate: got {rate_hz}; accepted: a positive sample rate in Hz")
    if time_unit is not None and time_unit not in rc.TIME_UNITS:
        raise UserError(f"--time-unit: got {time_unit!r}; accepted: {', '.join(rc.TIME_UNITS)}")
    with open(path, "rb") as fh:
        magic = fh.read(2)
    if magic == b"PK":
        return _npz_stream(path, override, axes, time_column, rate_hz, time_unit, unit, block)
    if is_log(path):
        raise NotStreamed(f"{src}: a recorder log is read whole")
    scratch = TempFolder("input", workdir)
    st = None
    try:
        gz, default = magic == b"\x1f\x8b", _unit(override)
        st = _parse(path, scratch, gz, override, default, axes, unit, rate_hz, time_column, target_axes(override))
        st.rate_hz, st.time_unit = rate_hz, time_unit
        _check(st, override, time_unit, chosen=bool(axes), model_axes=model_axes, block=block)
    except BaseException:  # Ctrl-C too: the store goes with the error
        if st is not None:
            st.close()
        scratch.close()
        raise
    return st


def _parse(path: Path, scratch: TempFolder, gz: bool, override, default, axes, unit, rate_hz, time_column, names=None):
    """The CSV's numbers and lines into the store, by the whole reader's parser."""
    folder = scratch.path
    src = str(path)
    size = path.stat().st_size
    n, head, first_line = 0, None, None  # first_line: while row k is on line first_line + k, no lines are stored
    with open(folder / "store.bin", "wb") as fs, open(folder / "lines.bin", "wb") as fl:
        for head, table, nums in rc.csv_pieces(path, axes, unit, rate_hz, time_column, gz, default, names):  # noqa: B007
            nums = np.ascontiguousarray(nums, dtype=np.int64)
            if n == 0 and len(nums):
                first_line = int(nums[0])
            if first_line is not None and len(nums) and not (nums[0] == first_line + n and np.all(np.diff(nums) == 1)):
                for a in range(0, n, 1 << 20):  # a comment or blank line among the rows: their lines from here on
                    fl.write((first_line + np.arange(a, min(a + (1 << 20), n), dtype=np.int64)).data)
                first_line = None
            if n == 0 and not gz:  # disk: the whole store from the first piece's rows per character
                est = int(len(nums) * max(1.0, size / rc.CHUNK_CHARS) * 1.05)
                need, free = est * 8 * (table.shape[1] + 1), shutil.disk_usage(folder).free
                if need > free:
                    raise UserError(
                        f"{src}: about {est} rows need {need / 1e9:.3g} GB of disk in {folder.parent} to be read "
                        f"in bounded memory; {free / 1e9:.3g} GB are free"
                    )
            try:
                fs.write(np.ascontiguousarray(table, dtype=np.float64).data)
                if first_line is None:
                    fl.write(nums.data)
            except OSError as exc:
                if exc.errno == errno.ENOSPC:
                    raise UserError(f"{src}: the disk in {folder.parent} filled up at row {n} of its store") from None
                raise
            n += len(nums)
    if n < 2:
        raise UserError(f"{src}: {n} data rows; a recording needs many more")
    st = Stream(src, n, override, np.array([]), head, folder, rate_hz, None, first_line=first_line)
    st._scratch = scratch
    st._fds = {k: os.open(folder / f"{k}.bin", os.O_RDONLY) for k in ("store", "lines")}
    return st


def _where(st: Stream, k: int) -> str:
    return f"sample {k} (line {int(st.rows(k, k + 1)[1][0])})"


def _check(st: Stream, override: Model | None, time_unit, *, chosen: bool, model_axes, block: int) -> None:
    """read_recording's time checks and read_input's model checks (inputs._on_model), block by block."""
    src, h = st.source, st.head
    tu = rc.csv_time_unit(h)
    if time_unit is not None:  # recording._with_time_unit
        if h.tcol is None:
            raise UserError(f"--time-unit: {src} has no time column (its time comes from the rate)")
        if tu not in (None, time_unit):
            raise UserError(f"--time-unit {time_unit}: the time column {h.tcol!r} says its unit is {tu}")
        tu = time_unit if tu is None else tu
    clock = _time_pass(st, block)
    if tu is None and h.tcol is not None:  # a calendar's clock (Unix time) says its unit by its numbers
        unit, said = rc.epoch_unit(src, h.tcol, clock.t0, clock.median(st.n - 1))
        if unit is not None:
            scale = rc.TIME_SCALE[unit]
            clock.t0, clock.tl, clock.dmin, clock.dmax = (
                x * scale for x in (clock.t0, clock.tl, clock.dmin, clock.dmax)
            )
            clock.vals = clock.vals * scale
            st.time_unit = tu = unit
            note(said)
    step = _clock_verdict(st, clock, tu)
    rate = (st.n - 1) / (clock.tl - clock.t0)
    # read_input._on_model: the model, its rate, its axes
    model = override if override is not None else load_model(None)
    rc.check_step(src, step, tu, model.rate_hz, str(model.source))
    model, names = model_axes(src, model, list(h.names), list(h.chosen), chosen)
    st.model, st.axis_names, st.t0, st.Ts = model, np.array(names), clock.t0, 1.0 / rate
    _grid_pass(st, rate, block)
    if list(h.chosen) != names:
        note(f"{src}: columns {', '.join(h.chosen)} -> model axes {', '.join(names)}")


@dataclass
class _Clock:
    """What the time pass learns: first and last stamp, the extreme steps, the distinct steps and their counts."""

    t0: float = 0.0
    tl: float = 0.0
    dmin: float = np.inf
    dmax: float = -np.inf
    vals: np.ndarray = field(default_factory=lambda: np.empty(0))
    counts: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))

    def add(self, dt: np.ndarray) -> int:
        """Count the steps ``dt``; returns how many distinct steps there are so far."""
        return self.add_counted(float(dt.min()), float(dt.max()), *np.unique(dt, return_counts=True))

    def add_counted(self, dmin: float, dmax: float, u: np.ndarray, c: np.ndarray) -> int:
        """:meth:`add` of steps already counted: their least and largest, the distinct ones ``u`` (any order)
        and their counts ``c``."""
        self.dmin, self.dmax = min(self.dmin, dmin), max(self.dmax, dmax)
        self.vals, inv = np.unique(np.concatenate((self.vals, u)), return_inverse=True)
        both = np.concatenate((self.counts, c))
        self.counts = np.bincount(inv, weights=both, minlength=len(self.vals)).astype(np.int64)
        return len(self.vals)

    def median(self, m: int) -> float:
        """The median of the m steps, as np.median takes it (the mean of the middle two for even m)."""
        cum = np.cumsum(self.counts)
        v1, v2 = (float(self.vals[np.searchsorted(cum, r, side="right")]) for r in ((m - 1) // 2, m // 2))
        return float(np.mean([v1, v2])) if m % 2 == 0 else v1


def _time_pass(st: Stream, block: int) -> _Clock:
    """recording._check_time's first checks over the store: time finite and increasing; the steps counted."""
    from accelnav.data.csvnum import csv_lib

    src, n, mod = st.source, st.n, csv_lib()
    clock, bad, back, n_back, prev = _Clock(), None, None, 0, None
    for s in range(0, n, block):
        t = st.times(s, min(s + block, n))
        if s == 0:
            clock.t0 = float(t[0])
        clock.tl = float(t[-1])
        # one C pass over the block where the C is built (acsv_time_block), else its numpy twin: the same numbers
        nonfinite, first_back, count_back, steps = (_steps_numpy if mod is None else partial(time_block, mod))(t, prev)
        if bad is None and nonfinite >= 0:
            bad = s + nonfinite
        first = s - (prev is not None)  # the sample index of dt[0]'s first sample
        n_dt = len(t) - (prev is None)
        if count_back:
            back = first + first_back if back is None else back  # dt index k: samples k, k + 1
            n_back += count_back
        if n_dt and bad is None:
            if steps is None:  # more distinct steps in the block than the C counts: numpy's
                dt = np.diff(t) if prev is None else np.diff(np.concatenate(([prev], t)))
                steps = (float(dt.min()), float(dt.max()), *np.unique(dt, return_counts=True))
            if clock.add_counted(*steps) > MAX_STEPS:
                raise NotStreamed(f"{src}: more than {MAX_STEPS} distinct time steps: its clock is read whole")
        prev = t[-1]
    if bad is not None:
        raise UserError(f"{src}: time is not a finite number at {_where(st, bad)}")
    if back is not None:
        ta, tb = (float(x) for x in st.raw_time(st.rows(back, back + 2)[0], back))
        raise UserError(
            f"{src}: time does not increase at {_where(st, back + 1)} (t = {ta:.6g} s, then {tb:.6g} s); "
            f"{n_back} such steps"
        )
    return clock


def _steps_numpy(t: np.ndarray, prev: float | None):
    """accelnav.data.csvnum.time_block's numbers by numpy (where no C is built; the C's oracle in the tests)."""
    finite = np.isfinite(t)
    dt = np.diff(t) if prev is None else np.diff(np.concatenate(([prev], t)))
    b = dt <= 0
    steps = None
    if finite.all() and len(dt):
        steps = (float(dt.min()), float(dt.max()), *np.unique(dt, return_counts=True))
    return (-1 if finite.all() else int(np.argmax(~finite)), int(np.argmax(b)) if b.any() else -1, int(b.sum()),
            steps)  # fmt: skip


def _clock_verdict(st: Stream, clock: _Clock, tu: str | None) -> float:
    """The median step; a clock too slow for seconds refused, one the whole reader must place not streamed."""
    src, col = st.source, st.head.tcol
    step = clock.median(st.n - 1)
    if col is None:
        return step
    if tu is None and 1.0 / step < rc.MIN_CLOCK_HZ:
        raise UserError(
            f"{src}: the time column {col!r} steps by {step:.6g} (median): read as seconds that is "
            f"{1.0 / step:.6g} Hz, too slow for an accelerometer; it looks like milliseconds: give --time-unit "
            "ms (or name the column t_ms), or convert it to seconds"
        )
    regular = clock.dmax <= rc.GAP_FACTOR * step and clock.dmin >= step / rc.GAP_FACTOR
    if not regular or st.rate_hz is not None:
        raise NotStreamed(f"{src}: its clock is placed on a grid by the whole reader (irregular, or --rate given)")
    return step


def _grid_pass(st: Stream, rate: float, block: int) -> None:
    """Counts converted, NaN, each sample on the grid (recording.on_grid), as the reader will give them."""
    from accelnav.data.csvnum import csv_lib

    src, n, t0, h = st.source, st.n, st.t0, st.head
    said, k_prev = False, -1
    weigh = bool(h.unit_from) and any(f != "name" for f in h.unit_from)  # a unit no name said: what the data say
    ratio, thr = rc.unit_ratios(h.units, st.model.max_accel_m_s2)
    mod, evidence = csv_lib(), 0.0
    for s in range(0, n, block):
        e = min(s + block, n)
        try:
            rec = st.block(s, e, lines=False)  # the lines are read only for a message
        except UserError:
            st.block(s, e)  # the same refusal, naming the line
            raise
        if not said and rec.notes:
            note(rec.notes[-1])  # the counts' conversion, once
            said = True
        # one C pass over the block where the C is built (acsv_grid_block), else its numpy twin: the same numbers
        grid = _grid_numpy if mod is None else partial(grid_block, mod)
        found, beyond = grid(rec.t, rec.accel, t0, st.Ts, k_prev, s == 0, ratio if weigh else ratio[:, :0], thr)
        nan, off, dup, gap, k_prev = (int(x) for x in found)
        located = replace(rec, lines=None if max(nan, off, dup) < 0 else st.rows(s, e)[1])
        if nan >= 0:
            raise UserError(f"{src}: {located.where(nan)} is not a number (NaN/inf); a gap in the data is not accepted")
        if off >= 0:
            raise UserError(
                f"{src}: {located.where(off)} (t = {rec.t[off]:.6g} s) is off the {rate:.6g} Hz sample grid by more "
                "than a quarter period: the timing jitters too much for a fixed-rate filter"
            )
        if dup >= 0:
            i = dup + (0 if s else 1)
            raise UserError(f"{src}: {located.where(i)} falls on the same sample period as the one before it")
        if gap:
            raise NotStreamed(f"{src}: samples missing from its clock are filled in by the whole reader")
        if weigh:
            evidence = evidence + rc.evidence_of(rec.accel, beyond, ratio)
    if weigh:
        rc.check_units(src, h.chosen, h.units, h.unit_from, evidence, st.model.max_accel_m_s2, str(st.model.source))


def _grid_numpy(t: np.ndarray, accel: np.ndarray, t0: float, Ts: float, k_prev: int, first: bool, ratio, thr):
    """accelnav.data.csvnum.grid_block's numbers by numpy (where no C is built; the C's oracle in the tests)."""
    nan = ~np.isfinite(accel)
    k = np.rint((t - t0) / Ts).astype(np.int64)
    off = np.abs(t - t0 - k * Ts) > 0.25 * Ts
    dk = np.diff(k) if first else np.diff(np.concatenate(([k_prev], k)))
    rows = nan.any(axis=1)
    found = [
        int(np.argmax(rows)) if rows.any() else -1,
        int(np.argmax(off)) if off.any() else -1,
        int(np.argmax(dk < 1)) if np.any(dk < 1) else -1,
        int(np.any(dk > 1)),
        int(k[-1]),
    ]
    mag = np.where(nan, 0.0, np.abs(accel))
    beyond = np.array(
        [[np.count_nonzero(~nan[:, j] & (mag[:, j] * r > thr)) for r in ratio[j]] for j in range(accel.shape[1])],
        dtype=np.int64,
    ).reshape(ratio.shape)
    return np.array(found, dtype=np.int64), beyond


def npz_rows(path: str | os.PathLike[str]) -> int | None:
    """Samples of an NPZ recording or run file from its ``accel`` member's header (None: not such an NPZ)."""
    import zipfile

    from accelnav.estimate.chunked import _stored_member

    path = Path(path)
    try:
        if not stat.S_ISREG(path.stat().st_mode):
            return None
        with zipfile.ZipFile(path) as zf:
            _, shape, _ = _stored_member(path, zf, "accel")
    except (OSError, zipfile.BadZipFile, KeyError, UserError):
        return None
    return int(shape[0]) if len(shape) == 2 else None


# what an NPZ recording may hold to be streamed: anything else (a unit, a rate, a model, raw counts, a
# simulation's truth) goes to the whole reader, which knows it
_NPZ_STREAMED = {"t", "accel", "axis_names", "clipped"}
_RUN_STREAMED = _NPZ_STREAMED | {"format", "model_toml", "model_source"}


class _NpzStream(Stream):
    """A :class:`Stream` whose rows are read from an uncompressed NPZ's ``t`` and ``accel`` members (no
    store: the file is one); the same checks as a CSV's, as if its columns were ``t`` and the axes in m/s^2.
    A run file (``format``) keeps its own time stamps, model and clipped flags, as load_run gives them."""

    # its columns are t and the axes in m/s^2 (scale 1, no counts): the passes read the members they need
    # as stored, not stacked into a CSV's table and scaled (three copies of the input per pass, a third of
    # the CPU of a 1e7-sample smooth, measured)

    def rows(self, s: int, e: int, lines: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        t, accel, _ = self._npz(s, e)
        table = np.column_stack((t, accel)) if e > s else np.empty((0, self.width))
        return table, (np.arange(s, e) + 1 if lines else None)

    def times(self, s: int, e: int) -> np.ndarray:
        t = self._npz.column("t", s, e)
        scale = rc.TIME_SCALE[rc.csv_time_unit(self.head)]
        return self._unit_time(t if scale == 1.0 else t * scale)

    def block(self, s: int, e: int, lines: bool = True) -> rc.Recording:
        h = self.head
        rec = rc.Recording(
            source=self.source, t=self.times(s, e), accel=self._npz.column("accel", s, e),
            axis_names=tuple(h.names), columns=tuple(h.chosen), units=tuple(h.units), rate_hz=float("nan"),
            lines=np.arange(s, e) + 1 if lines else None, first=s,
        )  # fmt: skip
        return rc.in_accel(rec, self.model)

    def __call__(self, s: int, e: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.run_file:  # as stored: its own clock, accel and clipped flags
            return self._npz(s, e)
        accel = self._npz.column("accel", s, e)  # the clock is the grid's: t is not read again
        t = self.t0 + np.arange(s, e) * self.Ts
        with np.errstate(invalid="ignore"):
            clipped = np.abs(accel) >= self.model.max_accel_m_s2 * (1 - 1e-9)
        if "clipped" in self._npz.members:
            clipped |= self._npz.part("clipped", s, e).astype(bool)
        return t, accel, clipped

    def close(self) -> None:
        self._npz.close()


def _npz_stream(path: Path, override, axes, time_column, rate_hz, time_unit, unit, block: int) -> Stream:
    """An uncompressed NPZ recording (t, accel, optional axis_names, clipped) or run file read block by block."""
    import zipfile

    from accelnav.data.recording import GAP_FACTOR, _Header
    from accelnav.estimate.chunked import NpzReader
    from accelnav.model.load import loads_model

    src = str(path)
    try:
        with zipfile.ZipFile(path) as zf:
            keys = {n.removesuffix(".npy") for n in zf.namelist()}
    except (OSError, zipfile.BadZipFile):
        raise NotStreamed(f"{src}: not a readable NPZ") from None
    run_file = "format" in keys
    options = [f for f, v in (("--axis", axes), ("--time-column", time_column), ("--rate", rate_hz),
                              ("--time-unit", time_unit), ("--unit", unit)) if v]  # fmt: skip
    if not keys <= (_RUN_STREAMED if run_file else _NPZ_STREAMED) or options or ("t" not in keys):
        raise NotStreamed(
            f"{src}: an NPZ with {', '.join(sorted(keys - _RUN_STREAMED)) or 'these options'} is read whole"
        )
    try:
        small = {k: np.load(path, allow_pickle=False)[k] for k in ("axis_names", "model_toml", "format") if k in keys}
    except (OSError, ValueError) as exc:
        raise UserError(f"{src}: not a readable NPZ ({exc})") from None
    reader = NpzReader(path)  # refuses compressed members and disagreeing shapes in one line
    try:
        k = reader.n_axes
        names = (
            [str(a) for a in small["axis_names"].reshape(-1)] if "axis_names" in small else [f"a{i}" for i in range(k)]
        )
        if len(names) != k:
            raise UserError(f"{src}: {len(names)} axis_names for {k} accel columns")
        if run_file and override is None:
            override = loads_model(str(small["model_toml"]), source=f"{src}:model_toml")
        if reader.n < 2:
            raise NotStreamed(f"{src}: {reader.n} samples")
        head = _Header(",", ["t", *names], "t", names, ["m/s^2"] * k, names, list(range(k + 1)), ("file",) * k)
        st = _NpzStream(src, reader.n, override, np.array([]), head, path.parent, None, None, kind="NPZ")
        st._npz, st.run_file = reader, run_file
        if run_file:  # load_run's and _with_model's checks: the model's axes and rate, no gap
            if names != [a.name for a in override.axes]:
                raise UserError(
                    f"{override.source}: axes {[a.name for a in override.axes]} do not match the run's {names}"
                )
            clock = _time_pass(st, block)
            step = clock.median(st.n - 1)
            if not abs(step * override.rate_hz - 1) <= 0.01:
                raise UserError(
                    f"{src}: the run is sampled at {1 / step:.6g} Hz but the model {override.source} has "
                    f"sampling.rate_hz = {override.rate_hz:g} Hz"
                )
            if clock.dmax > GAP_FACTOR * step:
                raise UserError(f"{src}: gap in time of {clock.dmax:.6g} s; a run file is not filled in")
            st.model, st.axis_names, st.t0 = override, np.array(names), clock.t0
            st.Ts = (clock.tl - clock.t0) / (st.n - 1)
        else:
            from accelnav.data.inputs import model_axes

            _check(st, override, None, chosen=False, model_axes=model_axes, block=block)
    except BaseException:
        reader.close()
        raise
    return st
