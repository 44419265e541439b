"""The plain smoother for a run of any length in bounded memory: chunks, a store on disk, streamed output.

The whole-array path (:func:`accelnav.estimate.fastsmooth.smooth_plain`) holds
gains and covariances for every sample, a few hundred bytes per sample and axis,
so its memory grows with the run. Here the same numbers are computed in three
passes over chunks (the C is acn_chunk_fwd, acn_chunk_bwd, acn_chunk_ru in
csrc/fastsmooth.c, the split of acn_plain_cov + acn_plain_data):

1. forward, chunk by chunk: filter means and covariances, the (a, eps) smoother
   gains; per sample 12 doubles (``ROW``) go to a store file on disk;
2. backward, chunk by chunk, last first: the smoothed (a, eps) and their
   covariances, written back into the store;
3. forward: smoothed r, u and their covariances, in closed form from the store.

With extra measurements (fixes, zero-velocity updates: whole :class:`fastsmooth.Extras` sliced per chunk,
or :class:`ChunkAids` made for each chunk alone, so that a run's millions of updates are never held at
once) an axis takes the general path instead, in two passes (acn_chunkg_fwd, acn_chunkg_bwd: the
steps of acn_general) over a store of the filter's posterior means, 4 doubles per sample (``GLROW``):
their covariances need no data, and the backward pass makes each chunk's again (acn_chunkg_cov) from its
first prior, the samples' validity and which aids the forward pass applied (at 1e7 samples with rests,
writing the 10 more doubles per sample to disk and reading them back was a third of the run). With
``covariances`` (written by the forward pass) the store keeps them: 14 doubles per sample (``GROW``).

Between chunks only a few numbers are carried (the filter's prior, the
smoother's state), so memory is the chunk buffers, whatever the run's length.
The chunk size comes from a memory budget (:data:`BUDGET`, 256 MB by default):
about 190 bytes per sample and axis are held per chunk.

Every number is computed by the same operations in the same order as on the
whole-array path, so the two agree to the last bit on one machine (the tests
allow 1e-12 relative, room for a compiler that contracts the two kernels'
multiply-adds differently).

Output: an uncompressed run-file NPZ with ``t``, ``axis_names``, ``accel``, ``clipped`` and the states
asked for (``stages``): the filter's and/or the smoother's ``filt_x``, ``smooth_x`` (n_axes, N, 4) and
their standard deviations ``filt_sd``, ``smooth_sd``; full covariances only when asked (``covariances``: at
1e8 samples each covariance array is 13 GB per axis, written chunk by chunk: every axis then takes the
general path, whose kernels hold each sample's covariances, acn_chunkg_fwd's priors and acn_chunkg_bwd's
smoothed ones; the plain path's lean store does not). Every member's size is known before the first chunk, so the
file is laid out up front and each chunk written once, in place (:mod:`accelnav.estimate.npzout`).

Where every sample so far was valid and the design's steady rows exist (fastsmooth.steady_gains), the
plain path's forward pass keeps a lean store (``LROW`` = 2 doubles: the filter's, then the smoothed, a
and eps) and the backward passes read the rest (gains, smoother gains, the filter's (a, eps)
covariances) from those rows, the same numbers in the same order. The smoothed (a, eps) covariance needs
no data: the r, u pass steps it again over each chunk from the covariance the backward pass carried into
that chunk (3 doubles a chunk), the same doubles, rather than keeping 3 more doubles a sample (a store's
fresh pages cost more than the kernels writing them: 0.8 s of system time for 800 MB, measured).
When the filter's states are not written (the smoother alone), only the run's last sample needs the
filter's r, u covariance: on steady rows it is not stepped per sample but jumped over each chunk (the
step is affine there; csrc/fastsmooth.c, steady_jump), which leaves every other output's bits alone and
moves the last sample's sds by less than the per-sample steps' own rounding drift (within 1e-9).

Asked for threads (:func:`accelnav.resources.threads`, ``ACCELNAV_THREADS``; one by default), plain axes (no
aids, no covariances) are worked on at once, one thread each, each with its own chunk buffers; the kernels
release the interpreter's lock and the writer takes pieces from any thread, so the file's bytes are those of
the axes in order. The compact output
(r, u and their sds at float32) is written by the kernels themselves, rounded as numpy's cast rounds, and the
smoothed (a, eps) covariance is not stepped again once it stands at its fixed point on the steady rows (the
same doubles: tests/estimate/test_smooth_compact.py).

The store is in memory when ``store_memory`` holds it (on disk, the write-back of a store the size of
the output throttled the run: 8 s of 17 at 1e7 samples, measured), else in a file in ``workdir``.
Disk needed: the output, plus the store when it is on disk; checked before any work starts, and the
temporary files are removed on success and on error.
"""

from __future__ import annotations

import os
import threading
import time
import zipfile
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor, wait
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from accelnav.errors import UserError
from accelnav.estimate import fastsmooth
from accelnav.estimate.kf import Measurement
from accelnav.estimate.npzout import NpzWriter
from accelnav.fileio import Output, TempFolder, free_bytes, output_target, pread_exact, pwrite_all
from accelnav.model.design import AxisDesign, axis_design
from accelnav.model.load import Model
from accelnav.progress import Progress
from accelnav.resources import threads

BUDGET = 256 << 20  # bytes of chunk buffers
PROGRESS_AFTER = 2.0  # s: a run that takes longer shows its passes' progress (accelnav.progress: stderr, not -q)
# peak bytes per sample and axis of `accelnav smooth` on the whole-array path (issue 24 measured 2.5 KB per
# two-axis sample at 1e6): what decides that a run goes to the bounded path
WHOLE_BYTES = 1250
ROW = 12  # doubles per sample and axis in the store (csrc/fastsmooth.c, ACN_ROW)
LROW = 2  # the same for all-valid samples of the plain path with steady rows (ACN_LROW)
GROW = 14  # the same for the general path (ACN_GROW): the posterior (the backward pass predicts again)
GLROW = 4  # ... without its covariance, made again per chunk (ACN_GLROW: the general path without covariances)
# held in memory per sample and axis during a chunk: store row, z, valid, two (4,) outputs, their copies
CHUNK_BYTES = 8 * GROW + 8 + 1 + 2 * 32 + 2 * 8
# --covariances, per sample, shared by the axes: two packed covariances and a prior mean (_Run.pa, pb, xb) and the
# (m, 16) unpacked copy written out
COV_BYTES = 8 * (10 + 10 + 4 + 16)
OUT_KEYS = ("filt_x", "filt_sd", "smooth_x", "smooth_sd")
# the compact output: states r, u (of r, u, a, eps) and their standard deviations, at float32 (24-bit
# mantissa: 6e-8 relative, 0.6 mm at 10 km); with t, 8 + 16 n_axes bytes per sample
COMPACT = (2, np.float32)
RUN_FORMAT = "accelnav-run/1"  # the CLI passes accelnav.data.runfile.FORMAT (a layer above this one)

# runs of at most this many samples work on their axes in order: a thread pool's start costs more than it saves
THREADS_FROM = 1 << 16


# read rows s..e of the input: (t (e-s,), accel (e-s, n_axes), clipped (e-s, n_axes) bool)
Reader = Callable[[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Piece:
    """One axis's aids of samples s..e-1 in the order the filter takes them (stably sorted by sample, as
    :meth:`fastsmooth.Extras.of` sorts the whole run's), ``gates`` beside them, and ``marked``: those whose
    application the run file's ``marks`` member records per sample (zero-velocity updates)."""

    ex: fastsmooth.Extras
    gates: np.ndarray
    marked: np.ndarray


class ChunkAids:
    """An axis's aids made chunk by chunk: ``count`` over the run (0: the axis takes the plain path) and
    :meth:`between`; the forward pass asks for each chunk once, in order (the lean general path's backward pass
    asks again, last chunk first: the result must be the same)."""

    count: int = 0
    nis_rows: int = 0  # rows this axis writes into smooth_bounded's ``nis`` member over the run

    def between(self, s: int, e: int) -> Piece:
        raise NotImplementedError

    def applied(self, piece: Piece, done: np.ndarray) -> None:
        """Which of ``piece``'s aids the filter applied (bool, its order)."""

    def innovations(
        self, piece: Piece, done: np.ndarray, y: np.ndarray, S: np.ndarray, t: np.ndarray, s: int
    ) -> np.ndarray:
        """``piece``'s aids seen by the filter: their innovations ``y`` and variances ``S`` (its order), applied or
        not (``done``), ``t`` the chunk's times from its first sample ``s`` (an aid's: ``t[k - s]``). Returns the
        chunk's rows of the ``nis`` member (r, 4), in order: :attr:`nis_rows` over the run in all."""
        return np.zeros((0, 4))


class _WholeAids(ChunkAids):
    """Extras given whole (a list of measurements, kf.Aids or fastsmooth.Extras) with their gates, sliced per
    chunk; which were applied is kept for the run, in the given order."""

    def __init__(self, ex: fastsmooth.Extras, gates) -> None:
        self.ex, self.count = ex, len(ex)
        g = None if gates is None or len(gates) == 0 else gates
        self.gates = np.zeros(len(ex)) if g is None else np.asarray(g, dtype=np.float64).reshape(len(ex))[ex.order]
        self.done = np.zeros(len(ex), dtype=bool)
        self.at = 0

    def between(self, s: int, e: int) -> Piece:
        a, b = int(np.searchsorted(self.ex.k, s)), int(np.searchsorted(self.ex.k, e))
        self.at = a
        ex = self.ex
        part = fastsmooth.Extras(ex.k[a:b], ex.h[a:b], ex.z[a:b], ex.R[a:b], ex.order[a:b])
        return Piece(part, self.gates[a:b], np.zeros(b - a, dtype=bool))

    def applied(self, piece: Piece, done: np.ndarray) -> None:
        self.done[self.at : self.at + len(done)] = done

    def given_order(self) -> np.ndarray:
        out = np.zeros(self.count, dtype=bool)
        out[self.ex.order] = self.done
        return out


def chunk_samples(n_axes: int, budget: int = BUDGET, covariances: bool = False) -> int:
    """Samples per chunk so that the chunk buffers of all axes fit ``budget`` bytes (2 at least)."""
    return max(2, int(budget) // sample_bytes(n_axes, covariances))


def sample_bytes(n_axes: int, covariances: bool = False) -> int:
    """Bytes held in memory per sample of a chunk: every axis's buffers and the input's t, accel, clipped (with
    ``covariances``, the shared buffers of a chunk's covariances: :data:`COV_BYTES`)."""
    return n_axes * CHUNK_BYTES + 8 + n_axes * 9 + (COV_BYTES if covariances else 0)


def memory_available() -> int:
    """Bytes of memory this machine can give now (MemAvailable; else physical memory)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def whole_bytes(n: int, n_axes: int) -> int:
    """Estimated peak memory of the whole-array path for n samples (see WHOLE_BYTES)."""
    return int(n) * n_axes * WHOLE_BYTES


def disk_needed(
    n: int,
    n_axes: int,
    n_general: int = 0,
    *,
    n_stages: int = 2,
    store: bool = True,
    full: bool = True,
    covariances: bool = False,
    marks: bool = False,
    nis_rows: int = 0,
) -> int:
    """Bytes of disk the bounded path needs at its peak: the store (``store``: smoothing; ``n_general`` of
    the axes on the general path, whose store is wider; ``covariances``: every axis) and the output, written
    once in place, as :func:`smooth_bounded` lays it out for ``full``, ``covariances``, ``marks`` and the
    ``nis`` member's rows (4 doubles each: by default one per rest, with ``--full`` one per zero-velocity
    update, up to 32 B per sample and axis)."""
    n_general = n_axes if covariances else n_general
    gw = GROW if covariances else GLROW
    return (
        (8 * n * (ROW * (n_axes - n_general) + gw * n_general) if store else 0)
        + n * output_bytes(n_axes, n_stages, full=full, covariances=covariances, marks=marks)
        + 32 * nis_rows
    )


def output_bytes(n_axes: int, n_stages: int, *, full: bool, covariances: bool = False, marks: bool = False) -> int:
    """Bytes per sample of :func:`smooth_bounded`'s output (its per-sample members; the small ones aside): t,
    each stage's x and sd (:data:`COMPACT`, or 4 states at float64 with the input echoed: ``full``), with
    ``covariances`` each stage's 4x4 covariance and the filter's prior mean and covariance (float64), and the
    marks (one byte per axis)."""
    k, dtype = (4, np.float64) if full or covariances else COMPACT
    per_axis = 2 * n_stages * k * np.dtype(dtype).itemsize + (9 if full or covariances else 0) + int(marks)
    if covariances:
        per_axis += 8 * (16 * n_stages + 4 + 16)
    return 8 + n_axes * per_axis


def array_reader(t: np.ndarray, accel: np.ndarray, clipped: np.ndarray) -> Reader:
    """A reader over arrays already in memory."""
    return lambda s, e: (t[s:e], accel[s:e], clipped[s:e])


def _stored_member(path: Path, zf: zipfile.ZipFile, name: str) -> tuple[int, tuple[int, ...], np.dtype]:
    """(offset of the data in the file, shape, dtype) of the uncompressed .npy member ``name``."""
    info = zf.getinfo(f"{name}.npy")
    if info.compress_type != zipfile.ZIP_STORED:
        raise UserError(f"{path}: {name!r} is compressed; reading in bounded memory needs it stored (np.savez)")
    with open(path, "rb") as fh:
        fh.seek(info.header_offset)
        local = fh.read(30)
        if local[:4] != b"PK\x03\x04":
            raise UserError(f"{path}: the zip entry of {name!r} is damaged")
        fh.seek(
            info.header_offset + 30 + int.from_bytes(local[26:28], "little") + int.from_bytes(local[28:30], "little")
        )
        try:
            version = np.lib.format.read_magic(fh)
            header = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
            if version not in header:
                raise ValueError(f"npy format version {version}")
            shape, fortran, dtype = header[version](fh)
        except ValueError as exc:
            raise UserError(f"{path}: {name!r} is not a plain array ({exc})") from None
        if fortran or dtype.hasobject:
            raise UserError(f"{path}: {name!r} is Fortran-ordered or of objects; not read in bounded memory")
        return fh.tell(), shape, dtype


class NpzReader:
    """A :data:`Reader` over an uncompressed NPZ recording of ``t`` (N,) and ``accel`` (N, n_axes), with
    ``clipped`` (N, n_axes) if present: each call reads its rows from the file, never a whole array.
    Use as a context manager (it holds the file open); ``n`` is the number of samples."""

    def __init__(self, path: str | Path) -> None:
        path = Path(path)
        try:
            with zipfile.ZipFile(path) as zf:
                names = zf.namelist()
                self.members = {
                    k: _stored_member(path, zf, k) for k in ("t", "accel", "clipped") if f"{k}.npy" in names
                }
        except (OSError, zipfile.BadZipFile) as exc:
            raise UserError(f"{path}: not a readable NPZ recording ({exc})") from None
        if "t" not in self.members or "accel" not in self.members:
            raise UserError(f"{path}: an NPZ recording needs 't' and 'accel'")
        t_shape, shape = self.members["t"][1], self.members["accel"][1]
        n = t_shape[0] if len(t_shape) == 1 else 0
        clip_ok = "clipped" not in self.members or self.members["clipped"][1] == shape
        if n < 1 or len(shape) != 2 or shape[0] != n or not clip_ok:
            raise UserError(f"{path}: shapes of t {t_shape} and accel {shape} disagree; accepted (N,), (N, n_axes)")
        self.n, self.n_axes = n, shape[1]
        self.fd = os.open(path, os.O_RDONLY)

    def part(self, key: str, s: int, e: int) -> np.ndarray:
        offset, shape, dtype = self.members[key]
        buf = np.empty((e - s, *shape[1:]), dtype=dtype)
        pread_exact(self.fd, buf, offset + s * int(np.prod(shape[1:])) * dtype.itemsize)
        return buf

    def column(self, key: str, s: int, e: int) -> np.ndarray:
        """Rows s..e of member ``key`` as float64 (read straight in, no copy, when it is stored so)."""
        return self.part(key, s, e).astype(np.float64, copy=False)

    def __call__(self, s: int, e: int):
        t, accel = self.column("t", s, e), self.column("accel", s, e)
        if "clipped" in self.members:
            return t, accel, self.part("clipped", s, e).astype(bool)
        return t, accel, np.zeros((e - s, self.n_axes), dtype=bool)

    def close(self) -> None:
        os.close(self.fd)

    def __enter__(self) -> NpzReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class NpzMember:
    """One uncompressed (n_axes, N, k) member of an NPZ, read at chosen samples without loading it."""

    def __init__(self, path: str | Path, name: str) -> None:
        path = Path(path)
        with zipfile.ZipFile(path) as zf:
            self.offset, self.shape, self.dtype = _stored_member(path, zf, name)
        self.fd = os.open(path, os.O_RDONLY)

    def rows_at(self, at: np.ndarray, state: int, span: int = 1 << 16) -> np.ndarray:
        """(n_axes, len(at)) values of ``state`` at samples ``at``: one read per group of them within ``span``
        samples, so that memory is ``span`` rows whatever ``at`` covers."""
        n_axes, n, k = self.shape
        out = np.empty((n_axes, len(at)))
        order = np.argsort(at, kind="stable")
        sa = np.asarray(at)[order]
        if len(sa) and (sa[0] < 0 or sa[-1] >= n):
            raise IndexError(f"samples {sa[0]}..{sa[-1]} outside 0..{n - 1}")
        for j in range(n_axes):
            i = 0
            while i < len(sa):
                lo = int(sa[i])
                e = int(np.searchsorted(sa, lo + span))
                buf = np.empty((int(sa[e - 1]) - lo + 1, k), dtype=self.dtype)
                pread_exact(self.fd, buf, self.offset + (j * n + lo) * k * self.dtype.itemsize)
                out[j, order[i:e]] = buf[sa[i:e] - lo, state]
                i = e
        return out

    def __enter__(self) -> NpzMember:
        return self

    def __exit__(self, *exc) -> None:
        os.close(self.fd)


@dataclass
class _Axis:
    j: int
    d: AxisDesign
    m: object  # acn_axis
    width: int  # doubles per store row: ROW (plain), GROW or GLROW (general, with or without covariances)
    carry_f: np.ndarray  # (14,) forward carry: the prior of the next sample
    aids: ChunkAids | None  # general path: its extras, given chunk by chunk
    # plain path: the stored transient (fastsmooth.steady_gains), used while every sample so far was valid
    # (the forward rows depend on the mask's prefix only); None after the first invalid one
    steady: fastsmooth.SteadyGains | None = None
    steady_rows: np.ndarray | None = None  # the same rows, kept for the backward passes of the lean chunks
    store: _Store | None = None  # rows of `width` doubles, sample s at byte 8 * width * s
    lean: _Store | None = None  # the lean store (LROW doubles per sample) of samples before lean_end
    lean_end: int = 0  # samples 0 .. lean_end - 1 went through acn_chunk_fwd_steady (all valid)
    # per lean chunk start: the smoothed (a, eps) covariance its backward pass started from (None: the run's end)
    cov_after: dict[int, np.ndarray | None] = field(default_factory=dict)
    carry_b: np.ndarray = field(default_factory=lambda: np.zeros(14))  # backward carry
    carry_r: np.ndarray = field(default_factory=lambda: np.zeros(11))  # r, u carry (plain)
    Pf0: np.ndarray = field(default_factory=lambda: np.zeros(10))
    Pfn: np.ndarray = field(default_factory=lambda: np.zeros(10))
    xf0: np.ndarray = field(default_factory=lambda: np.zeros(4))  # the run's first filter mean
    xfn: np.ndarray = field(default_factory=lambda: np.zeros(4))  # the run's last filter mean

    def close_stores(self) -> None:
        for st in (self.store, self.lean):
            if st is not None:
                st.close()

    marked: int = 0  # marked aids applied so far (zero-velocity updates)
    nis_at: int = 0  # the next row this axis writes into the run's ``nis`` member, and where its rows end
    nis_end: int = 0
    # the lean general path (GLROW), per chunk start: the prior covariance of its first sample, its valid samples
    # (packed bits; None: all), the aids the forward pass applied (packed bits) and their count and digest
    # (acn_aids_digest: the backward pass checks that it was given the same aids again): acn_chunkg_cov's inputs
    p_start: dict[int, tuple[np.ndarray, np.ndarray | None, np.ndarray, int, int]] = field(default_factory=dict)

    @property
    def general(self) -> bool:
        return self.width != ROW


class _Bufs:
    """One lane's chunk buffers: the store's scratch rows, a chunk's states and sds, the lean chunk's smoothed
    (a, eps) covariance (and its next sample's), the measurements and their valid mask."""

    def __init__(self, chunk: int) -> None:
        self.store = np.empty((chunk + 1) * GROW)
        self.xa, self.sa = np.empty((chunk, 4)), np.empty((chunk, 4))
        self.cov = np.empty((chunk + 1, 3))
        self.zc, self.ok = np.empty(chunk), np.empty(chunk, dtype=bool)
        self.bad = np.empty(chunk, dtype=bool)
        self.ends = np.empty((4, 4))  # a compact forward chunk's first and last states, then their sds
        self.extra = np.empty(0)  # the lean general path's second buffer (scratch)

    def rows(self, width: int, count: int) -> np.ndarray:
        return self.store[: count * width].reshape(count, width)

    def scratch(self, width: int) -> np.ndarray:
        """A second chunk buffer of ``width`` doubles per sample (the lean general path's means read from a store
        on disk while ``store`` holds the chunk's covariances), allocated on first use."""
        if len(self.extra) < len(self.zc) * width:
            self.extra = np.empty(len(self.zc) * width)
        return self.extra

    def compact(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """Two (count, 2) float32 arrays for a chunk's compact r, u and their sds, in ``sa``'s memory (the
        compact r, u pass writes nothing else there)."""
        flat = self.sa.reshape(-1).view(np.float32)
        half = len(flat) // 2
        return flat[: 2 * count].reshape(count, 2), flat[half : half + 2 * count].reshape(count, 2)


@dataclass
class _Run:
    """What the passes share: the kernels, the sizes, the output and the chunk buffers."""

    ffi: object
    lib: object
    n: int
    chunk: int
    out: NpzWriter
    axes: list[_Axis]
    smooth: bool  # False: the filter alone (no store, no backward passes)
    states: int  # states written per sample: 4 (r, u, a, eps) or 2 (r, u)
    first: dict[str, np.ndarray] = field(default_factory=dict)  # each output's sample 0, (n_axes, 4)
    last: dict[str, np.ndarray] = field(default_factory=dict)  # and its sample N-1 (for a summary line)
    tmp: Path | None = None  # the folder of the stores on disk
    memory_left: int = 0  # bytes the stores not yet opened may take in memory
    on_disk: bool = False  # a store went to disk
    marks: str = ""  # the member of the samples where a marked aid was applied ("": none written)
    nis: str = ""  # the member of the aids' rows given by ChunkAids.innovations ("": none written)
    covariances: bool = False  # the full covariances written (filt_P, smooth_P, the filter's priors)
    tap: Callable | None = None  # tap(key, j, s, values): each output as it is written (j = -1: the marks, all axes)
    threads: int = 1  # axes worked on at once (plain axes only: see :meth:`each`)
    bufs: list[_Bufs] = field(init=False)
    pool: ThreadPoolExecutor | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        # allocated once and reused by every chunk: fresh pages cost more than the kernels here (a page
        # fault per 4 KiB: fresh memory filled at 0.2-0.8 GB/s against 2.5 GB/s for pages in use, measured).
        # Axes worked on at once have their own (CHUNK_BYTES counts them per axis); else the axes share one set
        plain = not (self.marks or self.covariances) and all(ax.aids is None for ax in self.axes)
        if self.threads > 1 and plain and len(self.axes) > 1:
            self.pool = ThreadPoolExecutor(min(self.threads, len(self.axes)), thread_name_prefix="accelnav-axis")
        self.bufs = [_Bufs(self.chunk) for _ in (self.axes if self.pool is not None else self.axes[:1])]
        self.marked = np.zeros((self.chunk, len(self.axes)) if self.marks else (0, 0), dtype=bool)
        # --covariances: a chunk's packed covariances (10 a sample) and the filter's prior means
        c = self.chunk if self.covariances else 0
        self.pa, self.pb, self.xb = np.empty((c, 10)), np.empty((c, 10)), np.empty((c, 4))
        self._lock = threading.Lock()  # memory_left, on_disk: stores opened by axes on several threads

    def buf(self, ax: _Axis) -> _Bufs:
        """The chunk buffers of axis ``ax`` (its own when axes run at once)."""
        return self.bufs[ax.j if self.pool is not None else 0]

    def each(self, work: Callable[[_Axis], None], axes: Sequence[_Axis] | None = None) -> None:
        """``work(ax)`` for every axis: on :attr:`threads` threads at once when every axis is plain (the
        kernels release the GIL and touch only their axis's carries, stores and buffers; the writer takes
        pieces from any thread), else in order. The first error is raised once all have returned."""
        axes = self.axes if axes is None else axes
        if self.pool is None:
            for ax in axes:
                work(ax)
            return
        futures = [self.pool.submit(work, ax) for ax in axes]
        wait(futures)  # every axis done before any error goes up: none may write while the output is dropped
        for f in futures:
            f.result()

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)

    def open_store(self, name: str, width: int, s: int) -> _Store:
        """A store of ``width`` doubles per sample for samples s.. (the earlier ones are never touched): in
        memory while the stores opened so far leave room for its rows, else on disk."""
        need = 8 * width * (self.n - s)
        with self._lock:
            in_memory = need <= self.memory_left
            if in_memory:
                self.memory_left -= need
            self.on_disk |= not in_memory
        return _Store(self.tmp / f"{name}.bin", 8 * width * self.n, in_memory)

    def full_store(self, ax: _Axis, s: int) -> _Store:
        """Axis ``ax``'s full store, opened at sample s (its first sample off the lean path) if not yet."""
        if ax.store is None:
            ax.store = self.open_store(f"store-{ax.j}", ax.width, s)
        return ax.store

    def put_cov(self, key: str, j: int, s: int, packed: np.ndarray) -> None:
        """Rows s.. of axis j of the (n_axes, N, 4, 4) output ``key`` from their (m, 10) packed covariances,
        unpacked as the one-chunk path does (engine._Out.put)."""
        full = np.take(packed, fastsmooth.UNPACK, axis=1)
        self.out.write(key, 16 * (j * self.n + s), full)

    def ptr(self, a: np.ndarray, ctype: str = "double *"):
        return fastsmooth._ptr(self.ffi, a, ctype)

    def put_rows(
        self, key: str, j: int, s: int, data: np.ndarray, head: np.ndarray, tail: np.ndarray | None = None
    ) -> None:
        """Rows s.. of axis j of ``key`` as written (``states`` values a sample); ``head``, ``tail``: the 4 values
        (r, u, a, eps) of the rows' first and last sample, kept when those are the run's first and last."""
        self.out.write(key, self.states * (j * self.n + s), data)
        if len(data) and s == 0:
            self.first.setdefault(key, np.zeros((len(self.axes), 4)))[j] = head
        if len(data) and s + len(data) == self.n and tail is not None:
            self.last.setdefault(key, np.zeros((len(self.axes), 4)))[j] = tail

    def put(self, key: str, j: int, s: int, data: np.ndarray) -> None:
        """Rows s.. of axis j of the (n_axes, N, states) output ``key``, from their (m, 4) values."""
        k, data = self.states, np.atleast_2d(data)
        self.out.write(key, k * (j * self.n + s), data if k == 4 else data[:, :k])
        if self.tap is not None:
            self.tap(key, j, s, data)
        if len(data) and s == 0:
            self.first.setdefault(key, np.zeros((len(self.axes), 4)))[j] = data[0]
        if len(data) and s + len(data) == self.n:
            self.last.setdefault(key, np.zeros((len(self.axes), 4)))[j] = data[-1]


def fresh_pages(nbytes: int) -> np.ndarray:
    """``nbytes`` of fresh memory for a store (or another large array filled once), in private 4 KiB pages taken
    as rows are written (an untouched page costs nothing). Neither a shared mapping (mmap's default, shmem:
    where shmem_enabled is "never", the usual setting, it never gets huge pages and its faults cost more) nor
    np.empty (numpy asks huge pages for it, and where the kernel compacts memory to give them the faults stall):
    320 MB, the store of 1e7 samples x 2 axes, took 0.21-0.26 s of CPU private, 0.32-0.38 s shared, 0.05-0.9 s
    in huge pages (measured)."""
    import mmap

    if nbytes < 1 << 21:
        return np.empty(nbytes, dtype=np.uint8)
    private = getattr(mmap, "MAP_PRIVATE", None)
    m = mmap.mmap(-1, nbytes) if private is None else mmap.mmap(-1, nbytes, flags=private | mmap.MAP_ANONYMOUS)
    return np.frombuffer(m, dtype=np.uint8)


def fresh_array(shape: tuple[int, ...], dtype=np.float64) -> np.ndarray:
    """An uninitialised array of ``shape`` in :func:`fresh_pages` (a record-sized array filled once: the rest
    detector's and the decision's, whose np.empty pages faulted at a third of the speed, measured)."""
    dtype = np.dtype(dtype)
    return fresh_pages(int(np.prod(shape, dtype=np.int64)) * dtype.itemsize).view(dtype).reshape(shape)


class _Store:
    """One axis's store: in memory when the caller's budget holds it (the disk's write-back then never
    throttles the run: at 1e7 samples its 1.6 GB on disk cost 8 s here, measured), else a file in the work
    folder. Memory is taken page by page as rows are written (an untouched page costs nothing)."""

    def __init__(self, path: Path, nbytes: int, in_memory: bool) -> None:
        self.mem = fresh_pages(nbytes) if in_memory else None
        self.fd = -1 if in_memory else os.open(path, os.O_RDWR | os.O_CREAT, 0o600)

    def read(self, buf: np.ndarray, pos: int) -> None:
        if self.mem is None:
            pread_exact(self.fd, buf, pos)
        else:
            flat = buf.reshape(-1).view(np.uint8)
            flat[:] = self.mem[pos : pos + flat.size]

    def rows(self, scratch: np.ndarray, width: int, s: int, count: int, fill: bool = True) -> np.ndarray:
        """Rows s..s+count-1 to work on: in memory, the store's own (the kernels work in place, no copy);
        on disk, ``scratch`` filled from the file (if ``fill``), to be written back by :meth:`done`."""
        if self.mem is not None:
            return self.mem[8 * width * s : 8 * width * (s + count)].view(np.float64).reshape(count, width)
        buf = scratch[: count * width].reshape(count, width)
        if fill:
            pread_exact(self.fd, buf, 8 * width * s)
        return buf

    def done(self, buf: np.ndarray, s: int) -> None:
        """Rows from :meth:`rows` starting at sample s, changed: back to the file (in memory: already there)."""
        if self.mem is None:
            pwrite_all(self.fd, np.ascontiguousarray(buf), 8 * buf.shape[1] * s)

    def close(self) -> None:
        """Free the store (its memory, or its disk before the output is finished)."""
        self.mem = None
        if self.fd >= 0:
            os.ftruncate(self.fd, 0)
            os.close(self.fd)
            self.fd = -1


def smooth_bounded(
    model: Model,
    n: int,
    read: Reader,
    out: str | Path | Output,
    *,
    axis_names: np.ndarray | None = None,
    extras: Sequence[Sequence[Measurement] | fastsmooth.Extras | ChunkAids] | None = None,
    gates: Sequence[Sequence[float] | None] | None = None,
    budget: int = BUDGET,
    chunk: int | None = None,
    workdir: str | Path | None = None,
    run_format: str = RUN_FORMAT,
    more: Callable[[list[np.ndarray]], dict[str, np.ndarray]] | None = None,
    stages: tuple[str, ...] = ("filt", "smooth"),
    store_memory: int = 0,
    full: bool = True,
    marks: str = "",
    nis: str = "",
    covariances: bool = False,
    tap: Callable[[str, int, int, np.ndarray], None] | None = None,
) -> dict:
    """Filter and RTS-smooth every axis of an n-sample run in bounded memory; write ``out``.

    ``read(s, e)`` gives rows s..e of (t, accel, clipped) (:func:`array_reader`, :class:`NpzReader`);
    ``extras[j]`` are axis j's extra measurements (fixes, zero-velocity updates) with ``gates[j]`` as in
    :func:`accelnav.estimate.fastsmooth.smooth_general`: an axis with extras takes the general path
    (a wider store), one without the plain path; a :class:`ChunkAids` gives its own, chunk by chunk.
    ``chunk`` overrides the chunk size from ``budget``;
    temporary files go to ``workdir`` (default: beside ``out``); ``run_format`` is the run file's format;
    ``more(applied)`` may give small arrays to write beside the others, from which extras were applied.
    ``stages``: the states written, ``filt`` (x[k|k]: filt_x, filt_sd) and ``smooth`` (x[k|N-1]:
    smooth_x, smooth_sd); without ``smooth`` only the forward pass runs (the filter, no store).
    ``store_memory``: bytes the store may take in memory (default 0: on disk, in ``workdir``).
    ``full``: write every state (r, u, a, eps) at float64 and the input (accel, clipped); else r and u and
    their standard deviations at float32 beside t (:data:`COMPACT`, the run file's ``/3`` form).
    ``marks``: the name of an (N, n_axes) bool member written chunk by chunk: the samples where a marked aid
    (:attr:`Piece.marked`) was applied.
    ``nis``: the name of an (R, 4) float64 member written chunk by chunk: each axis's
    :meth:`ChunkAids.innovations` rows in turn, axis 0's first (R: the axes' :attr:`ChunkAids.nis_rows`).
    ``covariances``: also each stage's full covariances ``filt_P``, ``smooth_P`` (n_axes, N, 4, 4) and, with
    ``filt``, the filter's priors ``filt_x_prior`` (n_axes, N, 4), ``filt_P_prior``, at float64 as the
    one-chunk path writes them (implies ``full``): every axis then takes the general path, whose kernels hold
    each sample's covariances (the plain path's lean store does not), written chunk by chunk.
    ``tap(key, j, s, values)``: each (n_axes, N, 4) output's rows s.. of axis j, all four states at float64 as
    computed (before the compact cut), and the marks' rows (j = -1), as they are written (a figure's envelope):
    with a tap the axes run one after the other and the compact output is cut from those doubles, not written at
    float32 by the kernels (the same bytes).
    Returns {"chunk": samples per chunk, "chunks": how many, "applied": per axis, which extras given whole were
    applied, in their given order (None for ChunkAids), "marked": per axis, marked aids applied, "first",
    "last": {output key: its (n_axes, 4) values at sample 0, N-1}, "store_in_memory": where the store was}.
    Refuses in one line (UserError) before any work when the disk cannot hold the store and the output.
    """
    n = int(n)
    if n < 1:
        raise UserError("bounded smoother: at least one sample is needed")
    if not set(stages) <= {"filt", "smooth"} or not stages:
        raise ValueError(f"stages: {stages!r}; accepted: filt, smooth or both")
    n_axes = len(model.axes)
    names = np.array([a.name for a in model.axes]) if axis_names is None else np.asarray(axis_names)
    chunk = int(chunk) if chunk is not None else chunk_samples(n_axes, budget)
    if chunk < 2:
        raise ValueError("chunk: at least 2 samples")
    exs = _chunk_aids(extras, gates, n_axes, n)
    designs = [axis_design(model, j) for j in range(n_axes)]
    general = [
        covariances or exs[j] is not None or bool(np.any(np.asarray(d.P0)[:2, 2:] != 0)) for j, d in enumerate(designs)
    ]
    full = full or covariances
    out = output_target(out)  # the output rule (accelnav.fileio), refused before any work
    workdir = Path(workdir) if workdir is not None else out.workdir
    smooth = "smooth" in stages
    # the disk is checked for the worst case: every store on disk but what fits in memory at its widest rows
    gw = GROW if covariances else GLROW
    worst_in_memory = smooth and 8 * n * (ROW * (n_axes - sum(general)) + gw * sum(general)) <= store_memory
    nis_rows = [a.nis_rows if a is not None and nis else 0 for a in exs]
    _check_disk(n, n_axes, sum(general), workdir, len(stages), smooth and not worst_in_memory,
                full=full, covariances=covariances, marks=bool(marks), nis_rows=sum(nis_rows))  # fmt: skip
    mod = fastsmooth._lib()
    ffi, lib = mod.ffi, mod.lib
    small = {"format": np.array(run_format), "model_toml": np.array(model.text),
             "model_source": np.array(str(model.source)), "axis_names": names}  # fmt: skip
    big = {"t": ((n,), np.float64)}
    if full:
        big.update(accel=((n, n_axes), np.float64), clipped=((n, n_axes), np.bool_))
    k, dtype = (4, np.float64) if full else COMPACT
    for st in stages:
        big[f"{st}_x"] = big[f"{st}_sd"] = ((n_axes, n, k), dtype)
        if covariances:
            big[f"{st}_P"] = ((n_axes, n, 4, 4), np.float64)
    if covariances and "filt" in stages:
        big.update(filt_x_prior=((n_axes, n, 4), np.float64), filt_P_prior=((n_axes, n, 4, 4), np.float64))
    if marks:
        big[marks] = ((n, n_axes), np.bool_)
    big.update({nis: ((sum(nis_rows), 4), np.float64)} if nis else {})
    with ExitStack() as stack:
        tmp = stack.enter_context(TempFolder("smooth", workdir))
        lanes = threads()  # asked first: a bad ACCELNAV_THREADS is refused whatever the run's length
        writer = stack.enter_context(NpzWriter(out, {**small, **big}))
        axes = [_axis(ffi, j, d, exs[j], general[j] and (GROW if covariances else GLROW), n)
                for j, d in enumerate(designs)]  # fmt: skip
        for ax in axes:
            stack.callback(ax.close_stores)
            ax.nis_at = sum(nis_rows[: ax.j])
            ax.nis_end = ax.nis_at + nis_rows[ax.j]
        run = _Run(ffi, lib, n, chunk, writer, axes, smooth, k, tmp=tmp, memory_left=store_memory, marks=marks,
                   nis=nis, covariances=covariances, tap=tap,
                   threads=lanes if n > THREADS_FROM and tap is None else 1)  # fmt: skip
        stack.callback(run.close)
        for ax in axes if smooth else []:
            # a lean store (all samples valid so far) first where the design has steady rows: 5 doubles per
            # sample, not 12; the full store is opened at the first sample that needs it (run.full_store)
            if ax.width == ROW and ax.steady is not None:
                ax.lean = run.open_store(f"lean-{ax.j}", LROW, 0)
            else:
                ax.lean = _Store(tmp / f"lean-{ax.j}.bin", 0, True)
                ax.store = run.open_store(f"store-{ax.j}", ax.width, 0)
        starts = list(range(0, n, chunk))
        t0 = time.monotonic()

        def bar(label: str, total: int, unit: str = "samples") -> Progress:  # drawn after PROGRESS_AFTER s
            return Progress(label, total, unit=unit, after=max(0.0, PROGRESS_AFTER - (time.monotonic() - t0)))

        with bar("forward" if smooth else "filter", n) as p:
            for s in starts:  # 1. forward: the filter; for the smoother, rows into each axis's store
                _forward(run, s, min(s + chunk, n), read, "filt" in stages)
                p.update(min(s + chunk, n))
        _check_nis(axes, nis)
        if smooth:
            with bar("backward", n) as p:
                for s in reversed(starts):  # 2. backward: the general smoother; the plain (a, eps) into the store
                    run.each(lambda ax, s=s: _backward(run, ax, s, min(s + chunk, n)))
                    p.update(n - s)
            with bar("r, u", n_axes, "axes") as p:
                done = []

                def ru(ax: _Axis) -> None:  # 3. plain path, forward: smoothed r, u
                    if ax.width == ROW:
                        _smooth_ru(run, ax, starts)
                    ax.close_stores()  # freed before the small arrays are added
                    with run._lock:
                        done.append(ax.j)
                        p.update(len(done))

                run.each(ru)
        applied = [
            (a.given_order() if isinstance(a, _WholeAids) else None) if a is not None else np.zeros(0, dtype=bool)
            for a in exs
        ]
        for key, arr in (more(applied) if more is not None else {}).items():
            writer.add(key, arr)
    return {
        "chunk": chunk, "chunks": len(starts), "applied": applied, "marked": [ax.marked for ax in axes],
        "first": run.first, "last": run.last, "store_in_memory": not run.on_disk,
    }  # fmt: skip


def _check_nis(axes: Sequence[_Axis], nis: str) -> None:
    """The ``nis`` member was laid out from the aids' nis_rows: a file with rows never written is refused."""
    short = [ax.j for ax in axes if ax.nis_at != ax.nis_end]
    if short:
        raise ValueError(f"axes {short}: fewer {nis} rows than their aids' nis_rows")


def _chunk_aids(extras, gates, n_axes: int, n: int) -> list[ChunkAids | None]:
    """Each axis's aids as :class:`ChunkAids` (None: none, the plain path); those given whole are sorted now."""
    exs: list[ChunkAids | None] = [None] * n_axes
    for j, e in enumerate(extras or []):
        if isinstance(e, ChunkAids):
            exs[j] = e if e.count else None
            continue
        ex = fastsmooth.Extras.of(e)
        if len(ex) and (ex.k[0] < 0 or ex.k[-1] >= n):
            raise UserError(f"bounded smoother: axis {j}: an extra measurement is outside samples 0..{n - 1}")
        g = gates[j] if gates is not None and j < len(gates) else None
        exs[j] = _WholeAids(ex, g) if len(ex) else None
    return exs


def _check_disk(n: int, n_axes: int, n_general: int, workdir: Path, n_stages: int, smooth: bool, **out) -> None:
    need = disk_needed(n, n_axes, n_general, n_stages=n_stages, store=smooth, **out)
    free = free_bytes(workdir)
    if need > free:
        raise UserError(
            f"bounded smoother: {n} samples x {n_axes} axes need {need / 1e9:.3g} GB of disk in {workdir} for the "
            f"store and the output; {free / 1e9:.3g} GB are free"
        )


def _axis(ffi, j: int, d: AxisDesign, aids: ChunkAids | None, general: int, n: int) -> _Axis:
    """``general``: the general path's store width (GROW or GLROW); 0: the plain path."""
    cf = np.concatenate([np.asarray(d.x0, dtype=np.float64), fastsmooth.pack(np.asarray(d.P0, dtype=float))])
    st = None if general else fastsmooth.steady_gains(d, n)
    return _Axis(
        j, d, fastsmooth._axis_struct(ffi, d), general or ROW, cf, aids, steady=st,
        steady_rows=None if st is None else st.rows,
    )  # fmt: skip


def _forward(run: _Run, s: int, e: int, read: Reader, write_filt: bool) -> None:
    """Samples s..e-1 of every axis through the filter; the input and the filter's output written."""
    n_axes = len(run.axes)
    t, accel, clipped = read(s, e)
    run.out.write("t", s, t)
    if "accel" in run.out.members:
        run.out.write("accel", s * n_axes, accel)
        run.out.write("clipped", s * n_axes, clipped)
    m = e - s
    if run.marks:
        run.marked[:m] = False

    def axis(ax: _Axis) -> None:
        b = run.buf(ax)
        zc, ok, bad = b.zc[:m], b.ok[:m], b.bad[:m]
        zc[:] = accel[:, ax.j]
        np.isfinite(zc, out=ok)
        np.logical_not(clipped[:, ax.j], out=bad)
        ok &= bad
        np.logical_not(ok, out=bad)
        np.copyto(zc, 0.0, where=bad)
        if ax.width == ROW and ax.steady is not None and not ok.all():
            ax.steady = None  # from here on the covariances differ from the all-valid ones
        lean = ax.width == ROW and ax.steady is not None
        width = LROW if lean else ax.width
        store = ax.lean if lean or not run.smooth else run.full_store(ax, s)
        # the filter alone keeps no store: its rows go to the scratch buffer and are dropped
        buf = store.rows(b.store, width, s, m, fill=False) if run.smooth else b.rows(width, m)
        compact = False
        if ax.general:
            _forward_general(run, ax, s, e, zc, ok, buf, write_filt, t)
        else:
            compact = _forward_plain(run, ax, s, e, zc, ok, buf, write_filt)
            if lean:
                ax.lean_end = e
        if run.smooth:
            store.done(buf, s)
        first, last = (b.ends[0], b.ends[1]) if compact else (b.xa[0], b.xa[m - 1])
        if write_filt and compact:
            x32, s32 = b.compact(m)
            run.put_rows("filt_x", ax.j, s, x32, b.ends[0], b.ends[1])
            run.put_rows("filt_sd", ax.j, s, s32, b.ends[2], b.ends[3])
        elif write_filt:
            run.put("filt_x", ax.j, s, b.xa[:m])
            run.put("filt_sd", ax.j, s, b.sa[:m])
        if s == 0 and not ax.general:  # the plain path's r, u pass starts from them (the general may not make them)
            ax.xf0 = first.copy()
        if e == run.n and not ax.general:
            ax.xfn = last.copy()

    run.each(axis)
    if run.marks:
        run.out.write(run.marks, s * n_axes, run.marked[:m])
        if run.tap is not None:
            run.tap(run.marks, -1, s, run.marked[:m])


def _piece(ax: _Axis, s: int, e: int) -> tuple[Piece | None, int]:
    """Axis ``ax``'s aids of samples s..e-1 (ChunkAids.between, a caller's own among them) and their count, checked
    before the kernels read them (:func:`checked_piece`)."""
    piece = ax.aids.between(s, e) if ax.aids is not None else None
    return piece, checked_piece(piece, ax.j, s, e)


def checked_piece(piece: Piece | None, j: int, s: int, e: int) -> int:
    """The count of a ChunkAids piece of samples s..e-1 on axis j, refused unless it is what the kernels read: within
    the chunk and sorted, h (ne, 4) and k, z, R, gates, marked (ne,) (a caller's own ChunkAids may give anything)."""
    ne = 0 if piece is None else len(piece.ex)
    if not ne:
        return 0
    ex = piece.ex
    shapes = [np.shape(a) for a in (ex.h, ex.k, ex.z, ex.R, piece.gates, piece.marked)]
    if shapes != [(ne, 4)] + [(ne,)] * 5:
        raise ValueError(f"axis {j}: the aids of samples {s}..{e - 1} have h, k, z, R, gates, marked of shapes "
                         f"{shapes}; accepted: ({ne}, 4), then ({ne},)")  # fmt: skip
    if ex.k[0] < s or ex.k[-1] >= e or np.any(ex.k[1:] < ex.k[:-1]):
        raise ValueError(f"axis {j}: the aids of samples {s}..{e - 1} are not sorted within them")
    return ne


def _forward_general(
    run: _Run,
    ax: _Axis,
    s: int,
    e: int,
    zc: np.ndarray,
    ok: np.ndarray,
    buf: np.ndarray,
    write_filt: bool = True,
    t: np.ndarray | None = None,
) -> None:
    p, m, b = run.ptr, e - s, run.buf(ax)
    piece, ne = _piece(ax, s, e)
    ek = np.ascontiguousarray(piece.ex.k - s, dtype=np.int64) if ne else np.zeros(1, dtype=np.int64)
    arrs = [piece.ex.h, piece.ex.z, piece.ex.R, piece.gates] if ne else [np.zeros(4)] * 4
    arrs = [np.ascontiguousarray(a, dtype=np.float64) for a in arrs]
    applied = np.zeros(max(ne, 1), dtype=np.uint8)
    ey, eS = np.zeros(max(ne, 1)), np.zeros(max(ne, 1))  # the aids' innovations and variances as the filter met them
    args = (ax.m, m, int(e == run.n), p(zc), p(ok.view(np.uint8), "unsigned char *"), ne,
            run.ffi.from_buffer("long[]", ek), *(p(a) for a in arrs), p(applied, "unsigned char *"),
            p(ax.carry_f), p(buf), p(b.xa), p(b.sa))  # fmt: skip
    nis = (p(ey), p(eS))
    if ax.width == GLROW:
        p0 = ax.carry_f[4:].copy()
        if not write_filt:  # the filter's states unwanted: not made
            args = (*args[:-2], run.ffi.NULL, run.ffi.NULL)
        run.lib.acn_chunkg_fwd_lean(*args, *nis)
        if run.smooth:  # what acn_chunkg_cov needs to make the chunk's covariances again
            digest = int(run.lib.acn_aids_digest(ne, args[6], p(arrs[0]), p(arrs[2])))  # ek, h, R
            ax.p_start[s] = (p0, None if ok.all() else np.packbits(ok), np.packbits(applied[:ne]), ne, digest)
    else:
        prior = (p(run.xb), p(run.pb)) if run.covariances else (run.ffi.NULL, run.ffi.NULL)
        run.lib.acn_chunkg_fwd(*args, *prior, *nis)
    if run.covariances and "filt_P" in run.out.members:
        run.put_cov("filt_P", ax.j, s, buf[:m, 4:])
        run.out.write("filt_x_prior", 4 * (ax.j * run.n + s), run.xb[:m])
        run.put_cov("filt_P_prior", ax.j, s, run.pb[:m])
    if ne:
        done = applied[:ne].view(bool)  # the kernel's 0 or 1
        ax.aids.applied(piece, done)
        rows = ax.aids.innovations(piece, done, ey[:ne], eS[:ne], np.full(m, np.nan) if t is None else t, s)
        if run.nis and len(rows):
            if ax.nis_at + len(rows) > ax.nis_end:
                raise ValueError(f"axis {ax.j}: more {run.nis} rows than its aids' nis_rows")
            run.out.write(run.nis, 4 * ax.nis_at, np.ascontiguousarray(rows, dtype=np.float64))
            ax.nis_at += len(rows)
        hit = done & piece.marked
        ax.marked += int(hit.sum())
        if run.marks:
            run.marked[piece.ex.k[hit] - s, ax.j] = True


def _forward_plain(
    run: _Run, ax: _Axis, s: int, e: int, zc: np.ndarray, ok: np.ndarray, buf: np.ndarray, states: bool
) -> bool:
    """``states``: the filter's states are written; without them the steady kernel writes only the chunk's first
    and last and jumps its covariance over the steady samples (no step per sample: acn_chunk_fwd_steady).
    Returns True when the steady kernel wrote the compact states at float32 (:meth:`_Bufs.compact`, the
    chunk's first and last full rows in ``ends``), as the compact output wants them."""
    p, m, last, b = run.ptr, e - s, int(e == run.n), run.buf(ax)
    tail = (p(ax.carry_f), p(buf), p(b.xa), p(b.sa), p(ax.Pf0), p(ax.Pfn))
    compact = states and run.states == 2 and ax.steady is not None and run.tap is None  # a tap reads the doubles
    if compact:
        ends, f32 = b.ends, [p(a, "float *") for a in b.compact(m)]
        sr = ax.steady.rows
        rc = run.lib.acn_chunk_fwd_steady(
            ax.m, s, m, last, p(zc), p(sr), len(sr), *tail[:2], p(ends[0:2]), p(ends[2:4]), *tail[4:], *f32
        )  # fmt: skip
    elif ax.steady is not None:
        sr = ax.steady.rows
        sd = tail[3] if states else run.ffi.NULL
        f = run.ffi.NULL
        rc = run.lib.acn_chunk_fwd_steady(ax.m, s, m, last, p(zc), p(sr), len(sr), *tail[:3], sd, *tail[4:], f, f)
    else:
        rc = run.lib.acn_chunk_fwd(ax.m, s, m, last, p(zc), p(ok.view(np.uint8), "unsigned char *"), *tail)
    if rc != 0:
        raise UserError(f"bounded smoother: the (a, eps) prior covariance is singular at sample {-rc}")
    return compact


def _backward(run: _Run, ax: _Axis, s: int, e: int) -> None:
    """Samples e-1..s: the general path's smoother outright, the plain path's (a, eps) into its store."""
    p, m, last, b = run.ptr, e - s, int(e == run.n), run.buf(ax)
    if ax.general:
        if ax.width == GLROW:
            pst = b.store[: 10 * m]  # the chunk's filter covariances, made again
            _chunk_cov(run, ax, s, e, pst)
            buf = ax.store.rows(b.scratch(GLROW), GLROW, s, m)
            rc = run.lib.acn_chunkg_bwd_lean(ax.m, s, m, last, p(buf), p(pst), p(ax.carry_b), p(b.xa), p(b.sa))
        else:
            buf = ax.store.rows(b.store, GROW, s, m)
            ps = p(run.pa) if run.covariances else run.ffi.NULL
            rc = run.lib.acn_chunkg_bwd(ax.m, s, m, last, p(buf), p(ax.carry_b), p(b.xa), p(b.sa), ps)
        if rc != 0:
            raise UserError(f"bounded smoother: the prior covariance is not positive definite at {-rc}")
        if run.covariances:
            run.put_cov("smooth_P", ax.j, s, run.pa[:m])
        run.put("smooth_x", ax.j, s, b.xa[:m])
        run.put("smooth_sd", ax.j, s, b.sa[:m])
    elif s < ax.lean_end:
        buf = ax.lean.rows(b.store, LROW, s, m)
        sr = ax.steady_rows
        ax.cov_after[s] = None if last else ax.carry_b[2:5].copy()
        run.lib.acn_chunk_bwd_lean(ax.m, s, m, last, p(sr), len(sr), p(buf), p(ax.carry_b))
        ax.lean.done(buf, s)
    else:
        buf = ax.store.rows(b.store, ROW, s, m)
        run.lib.acn_chunk_bwd(ax.m, m, last, p(buf), p(ax.carry_b))
        ax.store.done(buf, s)


def _chunk_cov(run: _Run, ax: _Axis, s: int, e: int, pst: np.ndarray) -> None:
    """The filter's posterior covariances of samples s..e-1 (packed, into ``pst``) made again (acn_chunkg_cov) from
    what the forward pass kept of the chunk, its aids asked for again."""
    p, m = run.ptr, e - s
    p0, ok_bits, done_bits, n_done, digest = ax.p_start.pop(s)
    piece, ne = _piece(ax, s, e)
    ek = np.ascontiguousarray(piece.ex.k - s, dtype=np.int64) if ne else np.zeros(1, dtype=np.int64)
    h, R = (np.ascontiguousarray(a, dtype=np.float64) for a in ((piece.ex.h, piece.ex.R) if ne else (np.zeros(4),) * 2))
    ekb = run.ffi.from_buffer("long[]", ek)
    if ne != n_done or int(run.lib.acn_aids_digest(ne, ekb, p(h), p(R))) != digest:  # not the forward pass's aids
        raise ValueError(f"axis {ax.j}: the aids of samples {s}..{e - 1} differ from the forward pass's")
    done = np.unpackbits(done_bits, count=ne) if ne else np.zeros(1, dtype=np.uint8)
    valid = run.ffi.NULL if ok_bits is None else p(np.unpackbits(ok_bits, count=m), "unsigned char *")
    run.lib.acn_chunkg_cov(ax.m, m, int(e == run.n), valid, ne, ekb, p(h), p(R),
                           p(done, "unsigned char *"), p(p0), p(pst))  # fmt: skip


def _smooth_ru(run: _Run, ax: _Axis, starts: list[int]) -> None:
    """The plain path's third pass over one axis: smoothed r, u; the run's last sample is the filter's."""
    p, n, b = run.ptr, run.n, run.buf(ax)
    ax.carry_r[0:2] = ax.xf0[0:2]
    ax.carry_r[2], ax.carry_r[3], ax.carry_r[5] = ax.Pf0[0], ax.Pf0[1], ax.Pf0[4]
    for s in starts:
        e = min(s + run.chunk, n)
        m = e - s if e < n else e - s - 1  # transitions to the next sample; the last sample is written below
        if s < ax.lean_end:
            if e == ax.lean_end and e < n:  # the next sample is in the full store: its fields, lean order
                buf = b.rows(LROW, m + 1)
                ax.lean.read(buf[:m], 8 * LROW * s)
                nx = np.empty(ROW)
                ax.store.read(nx, 8 * ROW * e)
                buf[m] = nx[[0, 1]]
            else:
                buf = ax.lean.rows(b.store, LROW, s, m + 1)
            sr, after = ax.steady_rows, ax.cov_after[s]
            cov = b.cov[: e - s + 1]
            ends = run.ffi.NULL if after is None else p(after)  # None: the chunk ends the run
            run.lib.acn_chunk_cov_lean(ax.m, s, e - s, int(after is None), p(sr), len(sr), ends, p(cov))
            if after is not None:
                cov[e - s] = after  # the next sample's, for the chunk's last transition
            if run.states == 2 and run.tap is None:  # the compact output from the kernel, at float32 (no cast pass)
                x32, s32 = b.compact(m)
                v = ax.carry_r  # sample s's values as the full form has them, for the summary line
                head = (np.array([v[0], v[1], buf[0, 0], buf[0, 1]]), np.sqrt([v[2], v[5], cov[0, 0], cov[0, 2]]))
                f, out32 = run.ffi.NULL, (p(x32, "float *"), p(s32, "float *"))
                run.lib.acn_chunk_ru_lean(ax.m, s, m, p(buf), p(cov), p(sr), len(sr), p(ax.carry_r), f, f, *out32)
                run.put_rows("smooth_x", ax.j, s, x32, head[0])
                run.put_rows("smooth_sd", ax.j, s, s32, head[1])
                continue
            run.lib.acn_chunk_ru_lean(
                ax.m, s, m, p(buf), p(cov), p(sr), len(sr), p(ax.carry_r), p(b.xa), p(b.sa), run.ffi.NULL, run.ffi.NULL
            )  # fmt: skip
        else:
            buf = ax.store.rows(b.store, ROW, s, m + 1)
            run.lib.acn_chunk_ru(ax.m, m, p(buf), p(ax.carry_r), p(b.xa), p(b.sa))
        run.put("smooth_x", ax.j, s, b.xa[:m])
        run.put("smooth_sd", ax.j, s, b.sa[:m])
    run.put("smooth_x", ax.j, n - 1, ax.xfn)
    run.put("smooth_sd", ax.j, n - 1, np.sqrt(ax.Pfn[fastsmooth._DIAG]))
