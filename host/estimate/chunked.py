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

With extra measurements (fixes, zero-velocity updates; :class:`fastsmooth.Extras`, sliced per
chunk) an axis takes the general path instead, in two passes (acn_chunkg_fwd, acn_chunkg_bwd: the
steps of acn_general) over a store of 28 doubles per sample (``GROW``).

Between chunks only a few numbers are carried (the filter's prior, the
smoother's state), so memory is the chunk buffers, whatever the run's length.
The chunk size comes from a memory budget (:data:`BUDGET`, 256 MB by default):
about 190 bytes per sample and axis are held per chunk.

Every number is computed by the same operations in the same order as on the
whole-array path, so the two agree to the last bit on one machine (the tests
allow 1e-12 relative, room for a compiler that contracts the two kernels'
multiply-adds differently).

Output: an uncompressed ``accelnav-run/1`` NPZ with ``t``, ``axis_names``,
``accel``, ``clipped``, the filter's and smoother's states ``filt_x``,
``smooth_x`` (n_axes, N, 4) and their standard deviations ``filt_sd``,
``smooth_sd`` (n_axes, N, 4) instead of full covariances (at 1e8 samples each
covariance array would be 13 GB per axis). Each array is written in chunks to a
temporary ``.npy`` beside the output, then streamed into the NPZ. Disk needed:
the store plus twice the output; it is checked before any work starts, and the
temporary files are removed on success and on error.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import zipfile
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from accelnav.errors import UserError
from accelnav.estimate import fastsmooth
from accelnav.estimate.kf import Measurement
from accelnav.model.design import AxisDesign, axis_design
from accelnav.model.load import Model

BUDGET = 256 << 20  # bytes of chunk buffers
# peak bytes per sample and axis of `accelnav smooth` on the whole-array path (issue 24 measured 2.5 KB per
# two-axis sample at 1e6): what decides that a run goes to the bounded path
WHOLE_BYTES = 1250
ROW = 12  # doubles per sample and axis in the store (csrc/fastsmooth.c, ACN_ROW)
GROW = 28  # the same for the general path (ACN_GROW): posterior, and the prior of the next sample
# held in memory per sample and axis during a chunk: store row, z, valid, two (4,) outputs, their copies
CHUNK_BYTES = 8 * GROW + 8 + 1 + 2 * 32 + 2 * 8
OUT_KEYS = ("filt_x", "filt_sd", "smooth_x", "smooth_sd")
RUN_FORMAT = "accelnav-run/1"  # the CLI passes accelnav.data.runfile.FORMAT (a layer above this one)

# read rows s..e of the input: (t (e-s,), accel (e-s, n_axes), clipped (e-s, n_axes) bool)
Reader = Callable[[int, int], tuple[np.ndarray, np.ndarray, np.ndarray]]


def chunk_samples(n_axes: int, budget: int = BUDGET) -> int:
    """Samples per chunk so that the chunk buffers of all axes fit ``budget`` bytes (2 at least)."""
    return max(2, int(budget) // sample_bytes(n_axes))


def sample_bytes(n_axes: int) -> int:
    """Bytes held in memory per sample of a chunk: every axis's buffers and the input's t, accel, clipped."""
    return n_axes * CHUNK_BYTES + 8 + n_axes * 9


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


def disk_needed(n: int, n_axes: int, n_general: int = 0) -> int:
    """Bytes of disk the bounded path needs at its peak: the store and the output twice over
    (``n_general`` of the axes on the general path, whose store is wider)."""
    out = 8 * n * (1 + 4 * len(OUT_KEYS) * n_axes + n_axes) + 2 * n * n_axes
    return 8 * n * (ROW * (n_axes - n_general) + GROW * n_general) + 2 * out


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

    def _part(self, key: str, s: int, e: int) -> np.ndarray:
        offset, shape, dtype = self.members[key]
        buf = np.empty((e - s, *shape[1:]), dtype=dtype)
        _pread(self.fd, buf, offset + s * int(np.prod(shape[1:])) * dtype.itemsize)
        return buf

    def __call__(self, s: int, e: int):
        t, accel = self._part("t", s, e).astype(np.float64), self._part("accel", s, e).astype(np.float64)
        if "clipped" in self.members:
            return t, accel, self._part("clipped", s, e).astype(bool)
        return t, accel, np.zeros((e - s, self.n_axes), dtype=bool)

    def close(self) -> None:
        os.close(self.fd)

    def __enter__(self) -> NpzReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _NpyOut:
    """A .npy file of known shape filled by writes at offsets (no mapping: memory stays the caller's buffer)."""

    def __init__(self, path: Path, shape: tuple[int, ...], dtype) -> None:
        self.path, self.shape, self.dtype = path, shape, np.dtype(dtype)
        with open(path, "wb") as fh:
            np.lib.format.write_array_header_1_0(
                fh, {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False, "shape": shape}
            )
            self.offset = fh.tell()
        self.fd = os.open(path, os.O_RDWR)
        os.ftruncate(self.fd, self.offset + self.dtype.itemsize * int(np.prod(shape)))

    def write(self, item_index: int, data: np.ndarray) -> None:
        """Write ``data`` starting at flat element ``item_index``."""
        _pwrite(self.fd, np.asarray(data, dtype=self.dtype), self.offset + item_index * self.dtype.itemsize)

    def close(self) -> None:
        os.close(self.fd)


def write_npz_streamed(path: Path, members: dict[str, Path | np.ndarray], *, block: int = 16 << 20) -> None:
    """An uncompressed NPZ at ``path`` from .npy files (copied in blocks) and small arrays."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name, src in members.items():
            if isinstance(src, Path):
                with open(src, "rb") as fin, zf.open(f"{name}.npy", "w", force_zip64=True) as fout:
                    shutil.copyfileobj(fin, fout, block)
                src.unlink()
            else:
                with zf.open(f"{name}.npy", "w", force_zip64=True) as fout:
                    np.lib.format.write_array(fout, np.asanyarray(src), allow_pickle=False)


@dataclass
class _Axis:
    d: AxisDesign
    m: object  # acn_axis
    store: int  # fd of the store file
    width: int  # doubles per store row: ROW (plain) or GROW (general)
    carry_f: np.ndarray  # (14,) forward carry: the prior of the next sample
    ex: fastsmooth.Extras | None  # general path: its extras, sorted by sample
    gates: np.ndarray  # (n_extras,) in the sorted order
    applied: np.ndarray  # (n_extras,) uint8 in the sorted order
    carry_b: np.ndarray = field(default_factory=lambda: np.zeros(14))  # backward carry
    carry_r: np.ndarray = field(default_factory=lambda: np.zeros(11))  # r, u carry (plain)
    Pf0: np.ndarray = field(default_factory=lambda: np.zeros(10))
    Pfn: np.ndarray = field(default_factory=lambda: np.zeros(10))
    xfn: np.ndarray = field(default_factory=lambda: np.zeros(4))  # the run's last filter mean
    # plain path: the stored transient (fastsmooth.steady_gains), used while every sample so far was valid
    # (the forward rows depend on the mask's prefix only); None after the first invalid one
    steady: fastsmooth.SteadyGains | None = None

    def extras_in(self, s: int, e: int) -> slice:
        """The sorted extras of samples s..e-1."""
        if self.ex is None:
            return slice(0, 0)
        return slice(int(np.searchsorted(self.ex.k, s)), int(np.searchsorted(self.ex.k, e)))


def _pread(fd: int, buf: np.ndarray, pos: int) -> None:
    if buf.size == 0:
        return
    view = memoryview(buf).cast("B")
    while view:
        got = os.preadv(fd, [view], pos)
        if got <= 0:
            raise OSError(f"store: short read at byte {pos}")
        view, pos = view[got:], pos + got


def _pwrite(fd: int, buf: np.ndarray, pos: int) -> None:
    if buf.size == 0:
        return
    view = memoryview(np.ascontiguousarray(buf)).cast("B")
    while view:
        done = os.pwrite(fd, view, pos)
        view, pos = view[done:], pos + done


def smooth_bounded(
    model: Model,
    n: int,
    read: Reader,
    out: str | Path,
    *,
    axis_names: np.ndarray | None = None,
    extras: Sequence[Sequence[Measurement] | fastsmooth.Extras] | None = None,
    gates: Sequence[Sequence[float] | None] | None = None,
    budget: int = BUDGET,
    chunk: int | None = None,
    workdir: str | Path | None = None,
    run_format: str = RUN_FORMAT,
    more: Callable[[list[np.ndarray]], dict[str, np.ndarray]] | None = None,
) -> dict:
    """Filter and RTS-smooth every axis of an n-sample run in bounded memory; write ``out``.

    ``read(s, e)`` gives rows s..e of (t, accel, clipped) (:func:`array_reader`, :class:`NpzReader`);
    ``extras[j]`` are axis j's extra measurements (fixes, zero-velocity updates) with ``gates[j]`` as in
    :func:`accelnav.estimate.fastsmooth.smooth_general`: an axis with extras takes the general path
    (a wider store), one without the plain path. ``chunk`` overrides the chunk size from ``budget``;
    temporary files go to ``workdir`` (default: beside ``out``); ``run_format`` is the run file's format;
    ``more(applied)`` may give small arrays to write beside the others, from which extras were applied.
    Returns {"chunk": samples per chunk, "chunks": how many, "applied": per axis, which extras were
    applied, in their given order}. Refuses in one line (UserError) before any work when the disk
    cannot hold the store and the output.
    """
    n = int(n)
    if n < 1:
        raise UserError("bounded smoother: at least one sample is needed")
    out = Path(out)
    n_axes = len(model.axes)
    names = np.array([a.name for a in model.axes]) if axis_names is None else np.asarray(axis_names)
    chunk = int(chunk) if chunk is not None else chunk_samples(n_axes, budget)
    if chunk < 2:
        raise ValueError("chunk: at least 2 samples")
    exs = [None] * n_axes
    for j, e in enumerate(extras or []):
        ex = fastsmooth.Extras.of(e)
        if len(ex) and (ex.k[0] < 0 or ex.k[-1] >= n):
            raise UserError(f"bounded smoother: axis {j}: an extra measurement is outside samples 0..{n - 1}")
        exs[j] = ex if len(ex) else None
    designs = [axis_design(model, j) for j in range(n_axes)]
    general = [exs[j] is not None or bool(np.any(np.asarray(d.P0)[:2, 2:] != 0)) for j, d in enumerate(designs)]
    workdir = Path(workdir) if workdir is not None else out.resolve().parent
    need = disk_needed(n, n_axes, sum(general))
    free = shutil.disk_usage(workdir).free
    if need > free:
        raise UserError(
            f"bounded smoother: {n} samples x {n_axes} axes need {need / 1e9:.3g} GB of disk in {workdir} for the "
            f"store and the output; {free / 1e9:.3g} GB are free"
        )
    mod = fastsmooth._lib()
    ffi, lib = mod.ffi, mod.lib
    p = fastsmooth._ptr
    with ExitStack() as stack:
        tmp = Path(tempfile.mkdtemp(prefix=".accelnav-smooth-", dir=workdir))
        stack.callback(shutil.rmtree, tmp, True)
        outs = {k: _NpyOut(tmp / f"{k}.npy", (n_axes, n, 4), np.float64) for k in OUT_KEYS}
        t_out = _NpyOut(tmp / "t.npy", (n,), np.float64)
        a_out = _NpyOut(tmp / "accel.npy", (n, n_axes), np.float64)
        c_out = _NpyOut(tmp / "clipped.npy", (n, n_axes), np.bool_)
        for o in (*outs.values(), t_out, a_out, c_out):
            stack.callback(o.close)
        axes = []
        for j, d in enumerate(designs):
            fd = os.open(tmp / f"store-{j}.bin", os.O_RDWR | os.O_CREAT, 0o600)
            stack.callback(os.close, fd)
            cf = np.concatenate([np.asarray(d.x0, dtype=np.float64), fastsmooth.pack(np.asarray(d.P0, dtype=float))])
            ex = exs[j]
            ne = 0 if ex is None else len(ex)
            g = gates[j] if gates is not None and j < len(gates) and ex is not None else None
            g = None if g is None or len(g) == 0 else g
            eg = np.zeros(ne) if g is None else np.asarray(g, dtype=np.float64).reshape(ne)[ex.order]
            axes.append(
                _Axis(d, fastsmooth._axis_struct(ffi, d), fd, GROW if general[j] else ROW, cf,
                      ex, np.ascontiguousarray(eg), np.zeros(max(ne, 1), dtype=np.uint8),
                      steady=None if general[j] else fastsmooth.steady_gains(d, n))
            )  # fmt: skip
        starts = list(range(0, n, chunk))
        store = np.empty((chunk + 1) * GROW)
        xa, sa = np.empty((chunk, 4)), np.empty((chunk, 4))

        def rows(ax: _Axis, count: int) -> np.ndarray:
            return store[: count * ax.width].reshape(count, ax.width)

        # 1. forward: filter (and for the plain path the smoother gains), rows into each axis's store
        for s in starts:
            e = min(s + chunk, n)
            last = int(e == n)
            m = e - s
            t, accel, clipped = read(s, e)
            t_out.write(s, t)
            a_out.write(s * n_axes, accel)
            c_out.write(s * n_axes, clipped)
            for j, ax in enumerate(axes):
                z = np.ascontiguousarray(accel[:, j], dtype=np.float64)
                ok = np.isfinite(z) & ~np.asarray(clipped[:, j], dtype=bool)
                zc = np.where(ok, z, 0.0)
                vm = ok.view(np.uint8)
                buf = rows(ax, m)
                if ax.width == GROW:
                    sl = ax.extras_in(s, e)
                    ne = sl.stop - sl.start
                    ek = np.ascontiguousarray(ax.ex.k[sl] - s) if ne else np.zeros(1, dtype=np.int64)
                    arrs = [ax.ex.h[sl], ax.ex.z[sl], ax.ex.R[sl], ax.gates[sl]] if ne else [np.zeros(4)] * 4
                    arrs = [np.ascontiguousarray(a, dtype=np.float64) for a in arrs]
                    applied = ax.applied[sl.start : sl.start + max(ne, 1)] if ne else np.zeros(1, dtype=np.uint8)
                    lib.acn_chunkg_fwd(
                        ax.m, m, last, p(ffi, zc, "double *"), p(ffi, vm, "unsigned char *"), ne,
                        ffi.from_buffer("long[]", ek), *(p(ffi, a, "double *") for a in arrs),
                        p(ffi, applied, "unsigned char *"), p(ffi, ax.carry_f, "double *"), p(ffi, buf, "double *"),
                        p(ffi, xa, "double *"), p(ffi, sa, "double *"),
                    )  # fmt: skip
                else:
                    if ax.steady is not None and not ok.all():
                        ax.steady = None  # from here on the covariances differ from the all-valid ones
                    if ax.steady is not None:
                        sr = ax.steady.rows
                        rc = lib.acn_chunk_fwd_steady(
                            ax.m, s, m, last, p(ffi, zc, "double *"), p(ffi, sr, "double *"), len(sr),
                            p(ffi, ax.carry_f, "double *"), p(ffi, buf, "double *"), p(ffi, xa, "double *"),
                            p(ffi, sa, "double *"), p(ffi, ax.Pf0, "double *"), p(ffi, ax.Pfn, "double *"),
                        )  # fmt: skip
                    else:
                        rc = lib.acn_chunk_fwd(
                            ax.m, s, m, last, p(ffi, zc, "double *"), p(ffi, vm, "unsigned char *"),
                            p(ffi, ax.carry_f, "double *"), p(ffi, buf, "double *"), p(ffi, xa, "double *"),
                            p(ffi, sa, "double *"), p(ffi, ax.Pf0, "double *"), p(ffi, ax.Pfn, "double *"),
                        )  # fmt: skip
                    if rc != 0:
                        raise UserError(f"bounded smoother: the (a, eps) prior covariance is singular at sample {-rc}")
                _pwrite(ax.store, buf, 8 * ax.width * s)
                outs["filt_x"].write(4 * (j * n + s), xa[:m])
                outs["filt_sd"].write(4 * (j * n + s), sa[:m])
                if last:
                    ax.xfn = xa[m - 1].copy()

        # 2. backward: the general path's smoother outright; the plain path's (a, eps) into its store
        for s in reversed(starts):
            e = min(s + chunk, n)
            m = e - s
            for j, ax in enumerate(axes):
                buf = rows(ax, m)
                _pread(ax.store, buf, 8 * ax.width * s)
                if ax.width == GROW:
                    rc = lib.acn_chunkg_bwd(
                        ax.m, s, m, int(e == n), p(ffi, buf, "double *"), p(ffi, ax.carry_b, "double *"),
                        p(ffi, xa, "double *"), p(ffi, sa, "double *"),
                    )  # fmt: skip
                    if rc != 0:
                        raise UserError(f"bounded smoother: the prior covariance is not positive definite at {-rc}")
                    outs["smooth_x"].write(4 * (j * n + s), xa[:m])
                    outs["smooth_sd"].write(4 * (j * n + s), sa[:m])
                else:
                    lib.acn_chunk_bwd(ax.m, m, int(e == n), p(ffi, buf, "double *"), p(ffi, ax.carry_b, "double *"))
                    _pwrite(ax.store, buf, 8 * ax.width * s)

        # 3. plain path, forward: smoothed r, u; the run's last sample is the filter's (the whole path's convention)
        plain = [(j, ax) for j, ax in enumerate(axes) if ax.width == ROW]
        for _, ax in plain:
            ax.carry_r[2], ax.carry_r[3], ax.carry_r[5] = ax.Pf0[0], ax.Pf0[1], ax.Pf0[4]
        for s in starts if plain else []:
            e = min(s + chunk, n)
            m = e - s if e < n else e - s - 1  # transitions to the next sample; the last sample is written below
            for j, ax in plain:
                if s == 0:
                    ax.carry_r[0:2] = _first_xf(outs["filt_x"], j, n)
                buf = rows(ax, m + 1)
                _pread(ax.store, buf, 8 * ROW * s)
                lib.acn_chunk_ru(
                    ax.m, m, p(ffi, buf, "double *"), p(ffi, ax.carry_r, "double *"), p(ffi, xa, "double *"),
                    p(ffi, sa, "double *"),
                )  # fmt: skip
                outs["smooth_x"].write(4 * (j * n + s), xa[:m])
                outs["smooth_sd"].write(4 * (j * n + s), sa[:m])
                if e == n:
                    outs["smooth_x"].write(4 * (j * n + n - 1), ax.xfn)
                    outs["smooth_sd"].write(4 * (j * n + n - 1), np.sqrt(ax.Pfn[fastsmooth._DIAG]))
        for ax in axes:
            os.ftruncate(ax.store, 0)  # free the store's disk before the output is assembled
        applied = []
        for ax in axes:
            done = np.zeros(0 if ax.ex is None else len(ax.ex), dtype=bool)
            if ax.ex is not None:
                done[ax.ex.order] = ax.applied[: len(ax.ex)].astype(bool)
            applied.append(done)
        members: dict[str, Path | np.ndarray] = {
            "format": np.array(run_format),
            "model_toml": np.array(model.text),
            "model_source": np.array(str(model.source)),
            "axis_names": names,
            "t": t_out.path,
            "accel": a_out.path,
            "clipped": c_out.path,
            **{k: o.path for k, o in outs.items()},
            **(more(applied) if more is not None else {}),
        }
        part = tmp / "out.npz"
        write_npz_streamed(part, members)
        os.replace(part, out)
    return {"chunk": chunk, "chunks": len(starts), "applied": applied}


def _first_xf(f: _NpyOut, j: int, n: int) -> np.ndarray:
    """r, u of the filter at sample 0 of axis j, read back from the output being written."""
    buf = np.empty(2)
    _pread(f.fd, buf, f.offset + 8 * 4 * j * n)
    return buf
