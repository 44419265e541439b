"""Position fixes from a CSV file, mapped onto the samples of a run.

Format: a header row, then one fix per row, comma-separated:

    time_s,position_m,sigma_m            (a run with one axis)
    time_s,axis,position_m,sigma_m       (any run: axis is an axis name of the run)

time_s is on the run's clock (the run file's ``t``); each fix goes to the
nearest sample and must lie within half a sample period of the run. sigma_m is
the fix's standard deviation (> 0). Column order is free; other columns are
refused (a typo must not silently drop data). Bad files are refused with one
line naming the file, the row and what is accepted.
"""

from __future__ import annotations

import csv
import math
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


def read_fixes(path, t: np.ndarray, axis_names: list[str]) -> list[list[Measurement]]:
    """Position fixes of ``path`` as measurements per axis (index = column of the run)."""
    rows = read_table(path, required=("time_s", "position_m", "sigma_m"), optional=("axis",))
    t = np.asarray(t, dtype=np.float64)
    n = len(t)
    Ts = float(np.median(np.diff(t))) if n > 1 else 1.0
    if "axis" not in rows:
        if len(axis_names) != 1:
            raise UserError(
                f"{path}: the run has axes {', '.join(axis_names)}; add an 'axis' column naming the axis of each fix"
            )
        rows["axis"] = [axis_names[0]] * len(rows["time_s"])
    per_axis: list[list[Measurement]] = [[] for _ in axis_names]
    for i, (ts, ax, r, s) in enumerate(
        zip(rows["time_s"], rows["axis"], rows["position_m"], rows["sigma_m"], strict=True), start=2
    ):
        if ax not in axis_names:
            raise UserError(f"{path}: row {i}: axis {ax!r}; accepted: {', '.join(axis_names)}")
        if not s > 0:
            raise UserError(f"{path}: row {i}: sigma_m is {s:g}; accepted: a standard deviation > 0 (m)")
        if not (t[0] - Ts / 2 <= ts <= t[-1] + Ts / 2):
            raise UserError(f"{path}: row {i}: time_s {ts:g} is outside the run ({t[0]:g} to {t[-1]:g} s)")
        k = int(np.clip(np.searchsorted(t, ts), 1, max(n - 1, 1)))
        if n > 1 and abs(t[k - 1] - ts) <= abs(t[k] - ts):
            k -= 1
        k = min(k, n - 1)
        per_axis[axis_names.index(ax)].append(position_fix(k, r, s))
    return per_axis
