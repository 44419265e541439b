"""Position fixes from a CSV file, mapped onto the samples of a run.

Format: a header row, then one fix per row, comma-separated:

    time_s,position_m,sigma_m            (a run with one axis)
    time_s,axis,position_m,sigma_m       (any run: axis is an axis name of the run)

time_s is on the run's clock (the run file's ``t``); each fix goes to the
nearest sample and must lie within half a sample period of the run. The clock is read a piece at a
time (:class:`Clock`): a run of 1e8 samples is never held whole to place its fixes. sigma_m is
the fix's standard deviation (> 0). Column order is free; other columns are
refused (a typo must not silently drop data). Bad files are refused with one
line naming the file, the row and what is accepted.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from accelnav.errors import UserError
from accelnav.estimate.kf import Measurement, position_fix


def read_table(path, required: tuple[str, ...], optional: tuple[str, ...]) -> dict[str, list]:
    """Read a small CSV with a header; numbers for every column but ``axis``. One-line refusals."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: cannot read as text: {exc}") from None
    rows = [r for r in csv.reader(text.splitlines()) if r and any(c.strip() for c in r)]
    accepted = ", ".join(required + tuple(f"[{o}]" for o in optional))
    if not rows:
        raise UserError(f"{path}: empty; expected a header row with the columns {accepted}")
    header = [h.strip() for h in rows[0]]
    unknown = [h for h in header if h not in required + optional]
    missing = [h for h in required if h not in header]
    if unknown or missing or len(set(header)) != len(header):
        if unknown:
            what = f"unknown column {unknown[0]!r}"
        else:
            what = f"missing column {missing[0]!r}" if missing else "a repeated column"
        raise UserError(f"{path}: header: {what}; accepted columns: {accepted}")
    if len(rows) < 2:
        raise UserError(f"{path}: no data rows after the header")
    out: dict[str, list] = {h: [] for h in header}
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise UserError(f"{path}: row {i}: {len(row)} fields; the header has {len(header)}")
        for h, cell in zip(header, row, strict=True):
            cell = cell.strip()
            if h == "axis":
                out[h].append(cell)
                continue
            try:
                v = float(cell)
            except ValueError:
                raise UserError(f"{path}: row {i}: {h} is {cell!r}; accepted: a number") from None
            if not math.isfinite(v):
                raise UserError(f"{path}: row {i}: {h} is {cell!r}; accepted: a finite number")
            out[h].append(v)
    return out


@dataclass(frozen=True)
class Clock:
    """A run's increasing time stamps, read ``piece`` samples at a time by ``read(s, e)`` (t of samples s..e-1):
    what placing fixes and rest intervals on samples needs, without the run's t held whole. ``step``: the
    run's sample period (None: the median step of an array in memory, else the mean over the run)."""

    n: int
    read: Callable[[int, int], np.ndarray]
    step: float | None = None
    piece: int = 1 << 20

    @classmethod
    def of(cls, t: np.ndarray) -> Clock:
        t = np.asarray(t, dtype=np.float64)
        return cls(len(t), lambda s, e: t[s:e], float(np.median(np.diff(t))) if len(t) > 1 else 1.0)

    def pieces(self):
        """(s, t of samples s..) piece by piece; a clock that goes back is refused in one line."""
        last = -np.inf
        for s in range(0, self.n, self.piece):
            t = np.asarray(self.read(s, min(s + self.piece, self.n)), dtype=np.float64)
            if len(t) and not (t[0] >= last and np.all(t[1:] >= t[:-1])):
                raise UserError(
                    f"the run's time is not increasing near sample {s}; aids are placed on an increasing clock"
                )
            last = t[-1] if len(t) else last
            yield s, t

    def place(self, left: np.ndarray, right: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """One pass: (samples with t < each of ``left``, the t just below and just above each of ``left`` (NaN
        where none), samples with t <= each of ``right``, the run's first and last t): ``np.searchsorted`` on
        the whole clock, piece by piece."""
        left = np.asarray(left, dtype=np.float64)
        right = np.zeros(0) if right is None else np.asarray(right, dtype=np.float64)
        lo, hi = np.zeros(len(left), dtype=np.int64), np.zeros(len(right), dtype=np.int64)
        below, above = np.full(len(left), np.nan), np.full(len(left), np.nan)
        ends = [np.nan, np.nan]
        for s, t in self.pieces():
            if not len(t):
                continue
            ends[0] = t[0] if s == 0 else ends[0]
            ends[1] = t[-1]
            k = np.searchsorted(t, left, side="left")
            lo += k
            has = k > 0
            below[has] = t[k[has] - 1]
            first = (k < len(t)) & np.isnan(above)
            above[first] = t[k[first]]
            hi += np.searchsorted(t, right, side="right")
        return lo, below, above, hi, ends[0], ends[1]

    def period(self, first: float, last: float) -> float:
        if self.step is not None:
            return self.step
        return (last - first) / (self.n - 1) if self.n > 1 else 1.0


def read_fixes(path, t: np.ndarray | Clock, axis_names: list[str]) -> list[list[Measurement]]:
    """Position fixes of ``path`` as measurements per axis (index = column of the run), on the run's time
    ``t`` (an array, or a :class:`Clock` read a piece at a time).

    Checked and placed with whole-array operations (a GPS at 1 Hz gives 1e5 fixes on a day's run);
    the first bad row is refused, with the first of its faults, as a row-by-row check would.
    """
    rows = read_table(path, required=("time_s", "position_m", "sigma_m"), optional=("axis",))
    clock = t if isinstance(t, Clock) else Clock.of(t)
    n = clock.n
    if "axis" not in rows:
        if len(axis_names) != 1:
            raise UserError(
                f"{path}: the run has axes {', '.join(axis_names)}; add an 'axis' column naming the axis of each fix"
            )
        rows["axis"] = [axis_names[0]] * len(rows["time_s"])
    column = {a: j for j, a in enumerate(axis_names)}
    ax = np.array([column.get(a, -1) for a in rows["axis"]], dtype=np.int64)
    ts = np.asarray(rows["time_s"], dtype=np.float64)
    r = np.asarray(rows["position_m"], dtype=np.float64)
    s = np.asarray(rows["sigma_m"], dtype=np.float64)
    k, below, above, _, t0, tn = clock.place(ts)
    Ts = clock.period(t0, tn)
    faults = ((ax < 0), ~(s > 0), ~((t0 - Ts / 2 <= ts) & (ts <= tn + Ts / 2)))
    bad = np.logical_or.reduce(faults)
    if bad.any():
        i = int(np.argmax(bad))
        row = i + 2
        if faults[0][i]:
            raise UserError(f"{path}: row {row}: axis {rows['axis'][i]!r}; accepted: {', '.join(axis_names)}")
        if faults[1][i]:
            raise UserError(f"{path}: row {row}: sigma_m is {s[i]:g}; accepted: a standard deviation > 0 (m)")
        raise UserError(f"{path}: row {row}: time_s {ts[i]:g} is outside the run ({t0:g} to {tn:g} s)")
    # the nearest sample; a tie goes to the earlier one (k: the first sample at or after the fix)
    k = np.where((k > 0) & ((k == n) | (np.abs(below - ts) <= np.abs(above - ts))), k - 1, k)
    k = np.minimum(k, n - 1)
    per_axis: list[list[Measurement]] = [[] for _ in axis_names]
    for j, kk, rr, ss in zip(ax.tolist(), k.tolist(), r.tolist(), s.tolist(), strict=True):
        per_axis[j].append(position_fix(kk, rr, ss))
    return per_axis


def fixes_csv(rows: np.ndarray, axis_names) -> str:
    """The text :func:`read_fixes` reads, of fixes as rows [t, axis column, position, sigma] (the run file's
    ``fixes`` layout, and a simulated scenario's ``sim_fixes``); floats written to round-trip exactly."""
    rows = np.asarray(rows, dtype=np.float64).reshape(-1, 4)
    names = [str(a) for a in axis_names]
    lines = ["time_s,axis,position_m,sigma_m"]
    lines += [f"{t!r},{names[int(j)]},{r!r},{s!r}" for t, j, r, s in rows.tolist()]
    return "\n".join(lines) + "\n"
