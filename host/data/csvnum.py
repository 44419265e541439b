"""The numbers of a CSV piece in one C call: the reader's fast path, bit for bit numpy's reader's.

:func:`accelnav.data.recording.csv_pieces` parses a CSV body piece by piece (about CHUNK_CHARS of
whole lines); np.loadtxt took about three quarters of ``accelnav smooth``'s time on a CSV. The C
(csrc/csvnum.c, package data) reads a piece's bytes into a preallocated float64 array in one pass. It
accepts a strict subset of what np.loadtxt accepts today: plain decimal numbers (sign, digits, point
or the decimal comma the reader allows with ';' or tab, exponent) between optional spaces or tabs,
every line with the header's fields. What it does not accept (inf or nan spellings, an empty field,
quotes, other white space, a blank line, a field count that differs, a number longer than 400
characters) it reports by row and field, and the piece goes to the numpy reader, which reads it or
refuses it with today's message. Its doubles are correctly rounded as Python's float() rounds them
(csvnum.c says how), so both paths give the same bits.

The C is compiled into the wheel (host/native/kernels.py, named in setup.py); a source checkout whose
C was edited builds it on first use with the project's cffi builder. Without either (no C compiler),
:func:`csv_lib` is None and every piece takes the numpy path.
"""

from __future__ import annotations

import threading
from typing import NamedTuple

import numpy as np

from accelnav.native.cbuild import STRICT_FLAGS
from accelnav.native.kernels import CSVNUM, RICCATI_FLAGS, build, prebuilt
from accelnav.resources import package_dir

CSRC = package_dir("accelnav.data") / "csrc"  # package data: csvnum.c, csvnum.h

# csvnum.h's results
OK, FIELD, FIELDS, ROWS, ARGS = 0, 1, 2, 3, 4
WHY = {FIELD: "not a plain decimal number", FIELDS: "another number of fields, or blank",
       ROWS: "another number of lines", ARGS: "arguments disagree"}  # fmt: skip

_lock = threading.Lock()
_built: list = []  # [module or None] once tried


class Refused(NamedTuple):
    """Where the C stopped: the piece's row (from 0) and field (-1: the line as a whole), and why."""

    row: int
    col: int
    why: str


def _prebuilt():
    """The kernel compiled with the package (host/native/kernels.py), if it was built from this very C."""
    return prebuilt(CSVNUM, CSRC)


def _builder_built():
    """The kernel built from csrc/ by the project's cffi builder; None where that cannot be done."""
    return build(CSVNUM, CSRC, (*STRICT_FLAGS, *RICCATI_FLAGS[2:]), "acn_csvnum", required=False)


def csv_lib():
    """The kernel module: the package's own build, else built on first use; None without either."""
    with _lock:
        if not _built:
            _built.append(_prebuilt() or _builder_built())
        return _built[0]


def parse(
    mod, buf: bytes, delim: str, ncols: int, use: list[int], out: np.ndarray | None = None
) -> np.ndarray | Refused:
    """The numbers of fields ``use`` of every line of ``buf`` (whole lines split by ``\\n``, the last
    one without), (lines, len(use)) float64 (into ``out`` if given), through the kernel module ``mod``;
    or where it stopped."""
    if len(delim) != 1 or not 0 < ord(delim) < 128 or delim == "\n":
        return Refused(-1, -1, WHY[ARGS])
    if ncols < 1 or not use or any(not 0 <= j < ncols for j in use) or len(set(use)) != len(use):
        return Refused(-1, -1, WHY[ARGS])
    slot = np.full(ncols, -1, dtype=np.int64)
    slot[use] = np.arange(len(use))
    if out is None:
        out = np.empty((buf.count(b"\n") + 1, len(use)), dtype=np.float64)
    elif out.ndim != 2 or out.shape[1] != len(use) or out.dtype != np.float64 or not out.flags.c_contiguous:
        return Refused(-1, -1, WHY[ARGS])
    nrows = out.shape[0]  # the C refuses a buffer of another number of lines (ROWS)
    bad = np.empty(2, dtype=np.int64)
    ffi = mod.ffi
    rc = mod.lib.acsv_parse(
        ffi.from_buffer("uint8_t[]", buf),
        len(buf),
        ord(delim),
        int(delim != ","),  # with ';' or tab between fields a comma is a decimal comma
        ncols,
        ffi.from_buffer("int64_t[]", slot),
        len(use),
        nrows,
        ffi.from_buffer("double[]", out, require_writable=True),
        ffi.from_buffer("int64_t[]", bad, require_writable=True),
    )
    if rc != OK:
        return Refused(int(bad[0]), int(bad[1]), WHY.get(rc, f"result {rc}"))
    return out


def piece(text: str, delim: str, ncols: int, use: list[int]) -> np.ndarray | None:
    """The numbers of a piece of CSV text (whole lines joined by newlines) by the C, or None: no C
    module, or the piece holds something only the numpy reader reads or refuses (it then takes it)."""
    mod = csv_lib()
    if mod is None:
        return None
    # the table before the text's bytes: it takes the place the last piece's bytes left, and these, freed
    # on top of the heap, leave fewer holes (whole reader at 1e7 rows: peak RSS 830 -> 790 MB; numpy's 770-820)
    out = np.empty((text.count("\n") + 1, len(use)), dtype=np.float64)
    got = parse(mod, text.encode("utf-8", "surrogatepass"), delim, ncols, use, out)
    return None if isinstance(got, Refused) else got


def grid_block(
    mod, t: np.ndarray, accel: np.ndarray, t0: float, Ts: float, k_prev: int, first: bool, ratio: np.ndarray, thr: float
) -> tuple[np.ndarray, np.ndarray]:
    """The grid pass of one block of a streamed recording in one C pass (acsv_grid_block): (found, beyond),
    found = [first non-finite row, first row off the grid, first grid step below 1 (np.diff's index),
    1 if a step exceeds 1, the last row's grid index], -1 where none; beyond (n_axes, n_alt) the finite
    samples with |accel| * ratio > thr. ``ratio`` is (n_axes, n_alt); the numbers of
    accelnav.data.stream._grid_numpy, which tests/data/test_stream_grid.py holds it to."""
    t = np.ascontiguousarray(t, dtype=np.float64)
    accel = np.ascontiguousarray(accel, dtype=np.float64)
    ratio = np.ascontiguousarray(ratio, dtype=np.float64)
    m, k = accel.shape
    if t.shape != (m,) or ratio.ndim != 2 or ratio.shape[0] != k:
        raise ValueError(f"grid_block: t {t.shape}, accel {accel.shape}, ratio {ratio.shape} disagree")
    found = np.empty(5, dtype=np.int64)
    beyond = np.zeros((k, ratio.shape[1]), dtype=np.int64)
    ffi = mod.ffi
    rc = mod.lib.acsv_grid_block(
        m, k, ffi.from_buffer("double[]", t), ffi.from_buffer("double[]", accel), float(t0), float(Ts), int(k_prev),
        int(first), ratio.shape[1], ffi.from_buffer("double[]", ratio), float(thr),
        ffi.from_buffer("int64_t[]", found, require_writable=True),
        ffi.from_buffer("int64_t[]", beyond, require_writable=True),
    )  # fmt: skip
    if rc != OK:
        raise ValueError(f"grid_block: {WHY.get(rc, f'result {rc}')}")
    return found, beyond


STEPS_CAP = 1 << 16  # distinct time steps time_block counts in a block; a block with more goes to numpy


def time_block(mod, t: np.ndarray, prev: float | None, cap: int = STEPS_CAP):
    """The time pass of one block of stamps ``t`` (after ``prev``, the stamp before the block, or None) in one C
    pass (acsv_time_block): (first non-finite stamp, first step <= 0 by np.diff's index, steps <= 0, steps),
    -1 where none; steps = (least, largest, distinct steps, their counts), or None when a stamp is not
    finite, there is no step, or there are more than ``cap`` distinct steps. The numbers of
    accelnav.data.stream._steps_numpy, which tests/data/test_stream_grid.py holds it to."""
    t = np.ascontiguousarray(t, dtype=np.float64)
    m = len(t)
    cap = max(1, min(int(cap), m))
    found = np.empty(4, dtype=np.int64)
    span = np.empty(2)
    vals, counts = np.empty(cap), np.empty(cap, dtype=np.int64)
    ffi = mod.ffi
    w = {"require_writable": True}
    rc = mod.lib.acsv_time_block(
        m, ffi.from_buffer("double[]", t), int(prev is not None), 0.0 if prev is None else float(prev), cap,
        ffi.from_buffer("int64_t[]", found, **w), ffi.from_buffer("double[]", span, **w),
        ffi.from_buffer("double[]", vals, **w), ffi.from_buffer("int64_t[]", counts, **w),
    )  # fmt: skip
    if rc != OK:
        raise ValueError(f"time_block: {WHY.get(rc, f'result {rc}')}")
    nonfinite, back, n_back, distinct = (int(x) for x in found)
    n_dt = m - (prev is None)
    steps = None if distinct < 0 or n_dt == 0 else (float(span[0]), float(span[1]), vals[:distinct], counts[:distinct])
    return nonfinite, back, n_back, steps
