"""An uncompressed NPZ written in place, chunk by chunk, in any order: the smoother's output in bounded memory.

``np.savez`` needs every array whole in memory; writing each array to a temporary ``.npy`` and then
copying it into a zip (what the bounded smoother did) writes the output twice and reads it once more.
Here every member's size is known before any data exists (shape and dtype), so each member gets its
region of the file up front; chunks are written straight to their offsets as the passes produce them
(forward, backward, axis by axis), each chunk's CRC-32 taken from the buffer in hand, and the CRCs are
combined at the end (the zip needs one per member) with :func:`crc32_combine`. Then the local headers
and the central directory (zip64: members of any size) are written. numpy and zipfile read the result
as any NPZ, and check its CRCs.
"""

from __future__ import annotations

import io
import os
import queue
import struct
import zlib
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from accelnav.fileio import Output, OutputFile, pwrite_all, write_failure

_POLY = 0xEDB88320  # CRC-32 (zip), reflected
SLOTS = 3  # pieces in flight behind the caller (each a copy of one write: memory is SLOTS pieces)


def _multmodp(a: int, b: int) -> int:
    """a * b modulo the CRC polynomial (reflected bit order, as in zlib's crc32.c)."""
    m, p = 1 << 31, 0
    while True:
        if a & m:
            p ^= b
            if (a & (m - 1)) == 0:
                return p
        m >>= 1
        b = (b >> 1) ^ _POLY if b & 1 else b >> 1


_X2N = [1 << 30]  # x^(2^k) modulo the polynomial
for _ in range(31):
    _X2N.append(_multmodp(_X2N[-1], _X2N[-1]))


def crc32_combine(crc1: int, crc2: int, len2: int) -> int:
    """CRC-32 of A + B from crc1 = crc32(A), crc2 = crc32(B) and len(B) (zlib's crc32_combine)."""
    p, k, n = 1 << 31, 3, len2  # x^(8 len2): 2^3 bits per byte
    while n:
        if n & 1:
            p = _multmodp(_X2N[k & 31], p)
        n >>= 1
        k += 1
    return _multmodp(p, crc1) ^ crc2


def _npy_header(shape: tuple[int, ...], dtype: np.dtype) -> bytes:
    buf = io.BytesIO()
    header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": tuple(shape)}
    np.lib.format.write_array_header_1_0(buf, header)  # shapes of a few dims: far under its 64 KiB
    return buf.getvalue()


class _Member:
    def __init__(self, name: str, offset: int, head: bytes, nbytes: int) -> None:
        self.name = name.encode()
        self.local = offset  # the local header's offset
        self.data = offset + 30 + len(self.name) + 20  # the .npy's first byte (its header)
        self.head = len(head)  # bytes of the .npy header: element 0 is there
        self.size = len(head) + nbytes  # bytes of the .npy
        self.pieces: list[tuple[int, int, int]] = []  # (offset in the .npy, length, crc32)


class NpzWriter:
    """An NPZ at ``path`` of the given members: each a small array (written now) or ``(shape, dtype)``,
    filled later by :meth:`write` at flat element offsets, in any order. :meth:`close` checks that every
    byte was written, then writes the headers; the file appears at ``path`` only then, by the output rule
    (:class:`accelnav.fileio.OutputFile`: an exclusive temporary file beside it, renamed; a FIFO, a device
    or ``-`` gets the bytes copied from an unnamed temporary file). Use as a context manager: on error
    nothing is left, and an OSError (a full disk, in the output or a store written beside it) becomes
    one line."""

    def __init__(
        self, path: str | Path | Output, members: dict[str, np.ndarray | tuple[tuple[int, ...], object]]
    ) -> None:
        self.output = OutputFile(path, seekable=True)
        self.path = Path(str(path))
        self.fd = self.output.fd
        # large pieces are copied into one of SLOTS slots and written by a writer thread (their CRC by a
        # third) while the caller computes the next: the write, not the kernels, was the larger part of a
        # 1e7-sample smooth (pwrite 1.5 s beside 1.2-1.8 s of kernels, measured); the slots bound the memory.
        # Callers on several threads (the axes of a run, accelnav.estimate.chunked) may write at once: a slot
        # is taken from the queue of free ones and comes back only when its piece is on disk, so no two
        # callers ever fill the same slot
        self._writer = ThreadPoolExecutor(1)
        self._crc = ThreadPoolExecutor(1)  # the CRC beside the write: each was ~1 s of a 1e7-sample smooth
        self._free: queue.SimpleQueue[list] = queue.SimpleQueue()  # free slots: [buffer, its last piece's future]
        for _ in range(SLOTS):
            self._free.put([None, None])
        try:
            self._lay_out(members)
        except BaseException:
            self.abort()
            raise

    def _lay_out(self, members: dict) -> None:
        self.members: dict[str, _Member] = {}
        self.dtypes: dict[str, np.dtype] = {}
        small: list[tuple[str, np.ndarray]] = []
        offset = 0
        for name, spec in members.items():
            if isinstance(spec, np.ndarray):
                arr = np.asarray(spec, order="C")  # (ascontiguousarray makes a 0-d array 1-d)
                small.append((name, arr))
                shape, dtype = arr.shape, arr.dtype
            else:
                shape, dtype = tuple(int(s) for s in spec[0]), np.dtype(spec[1])
            if dtype.hasobject:
                raise ValueError(f"{name}: object arrays are not written")
            head = _npy_header(shape, dtype)
            m = _Member(f"{name}.npy", offset, head, dtype.itemsize * int(np.prod(shape)))
            self.members[name], self.dtypes[name] = m, dtype
            self._put(m, 0, head)
            offset = m.data + m.size
        self.end = offset
        os.ftruncate(self.fd, self.end)
        for name, arr in small:
            self.write(name, 0, arr)

    def _put(self, m: _Member, at: int, data) -> None:
        view = memoryview(data).cast("B")
        self._check(m, at, len(view))
        if len(view) < 1 << 20:
            self._write_piece(m, at, view)
            return
        slot, piece = self._slot(len(view))
        with self._owned(slot):
            piece[:] = view
            self._submit(slot, m, at, piece)

    @staticmethod
    def _check(m: _Member, at: int, nbytes: int) -> None:
        if at < 0 or at + nbytes > m.size:
            raise ValueError(f"{m.name.decode()}: bytes {at}..{at + nbytes} outside 0..{m.size}")

    def _slot(self, nbytes: int) -> tuple[list, memoryview]:
        """A free slot (its previous piece on disk), and its first ``nbytes`` to fill; the caller owns it
        until :meth:`_submit`."""
        slot = self._free.get()
        done, slot[1] = slot[1], None
        if done is not None:
            try:
                done.result()  # the slot's previous piece's error (a full disk, say) is raised here
            except BaseException:
                self._free.put(slot)
                raise
        if slot[0] is None or len(slot[0]) < nbytes:
            slot[0] = np.empty(nbytes, dtype=np.uint8)
        return slot, memoryview(slot[0])[:nbytes]

    @contextmanager
    def _owned(self, slot: list):
        """A slot taken by :meth:`_slot`: back to the queue if the caller fails before :meth:`_submit` gives it
        to the writer (else :meth:`_drain` would wait for it forever)."""
        try:
            yield
        except BaseException:
            if slot[1] is None:
                self._free.put(slot)
            raise

    def _submit(self, slot: list, m: _Member, at: int, piece: memoryview) -> None:
        crc = self._crc.submit(zlib.crc32, piece)
        slot[1] = fut = self._writer.submit(self._write_piece, m, at, piece, crc)
        fut.add_done_callback(lambda _, slot=slot: self._free.put(slot))  # free again once on disk

    def _write_piece(self, m: _Member, at: int, view: memoryview, crc=None) -> None:
        pwrite_all(self.fd, view, m.data + at)
        m.pieces.append((at, len(view), zlib.crc32(view) if crc is None else crc.result()))

    def _drain(self) -> None:
        """Wait for every piece in flight (every slot back in the queue); the first error among them is raised.
        Called once no caller writes any more."""
        slots = [self._free.get() for _ in range(SLOTS)]
        errors = []
        for slot in slots:
            if slot[1] is not None:
                try:
                    slot[1].result()
                except BaseException as exc:
                    errors.append(exc)
                slot[1] = None
            self._free.put(slot)
        if errors:
            raise errors[0]

    def write(self, name: str, item: int, data: np.ndarray) -> None:
        """Write ``data`` (cast to the member's dtype) starting at flat element ``item`` of member ``name``."""
        dt = self.dtypes[name]
        m = self.members[name]
        data = np.asarray(data)
        nbytes = data.size * dt.itemsize
        if nbytes >= 1 << 20:  # cast straight into a slot: one pass, no fresh array (a page fault per 4 KiB)
            self._check(m, m.head + item * dt.itemsize, nbytes)
            slot, piece = self._slot(nbytes)
            with self._owned(slot):
                dst = np.frombuffer(piece, dtype=dt).reshape(data.shape)
                if data.ndim == 2 and data.shape[1] <= 4 and not data.flags.c_contiguous:
                    # a few columns of wider rows (the compact r, u of (m, 4) states): numpy's loop runs per row
                    # there; per column the same casts take half the time (5.4 -> 2.7 ms for 6e5 rows, measured)
                    for c in range(data.shape[1]):
                        np.copyto(dst[:, c], data[:, c], casting="unsafe")
                else:
                    np.copyto(dst, data, casting="unsafe")
                self._submit(slot, m, m.head + item * dt.itemsize, piece)
            return
        arr = np.ascontiguousarray(data, dtype=dt)
        if arr.size:
            self._put(m, m.head + item * dt.itemsize, arr)

    def add(self, name: str, arr: np.ndarray) -> None:
        """A member made after the others (small: its bytes are written now, after the laid-out ones)."""
        arr = np.asarray(arr, order="C")
        head = _npy_header(arr.shape, arr.dtype)
        m = _Member(f"{name}.npy", self.end, head, arr.nbytes)
        self.members[name], self.dtypes[name] = m, arr.dtype
        self.end = m.data + m.size
        self._put(m, 0, head)
        self.write(name, 0, arr)

    def close(self) -> None:
        """Every member's CRC from its pieces (which must tile it), the headers, then the file in place."""
        self._drain()
        central = []
        for m in self.members.values():
            crc, pos = 0, 0
            for at, length, c in sorted(m.pieces):
                if at != pos:
                    raise ValueError(f"{m.name.decode()}: bytes {pos}..{at} were never written")
                crc, pos = crc32_combine(crc, c, length), pos + length
            if pos != m.size:
                raise ValueError(f"{m.name.decode()}: bytes {pos}..{m.size} were never written")
            # local header: version 4.5 (zip64), stored, 1980-01-01, sizes in the zip64 extra field
            local = struct.pack("<IHHHHHIIIHH", 0x04034B50, 45, 0, 0, 0, 0x21, crc, 0xFFFFFFFF, 0xFFFFFFFF,
                                len(m.name), 20)  # fmt: skip
            pwrite_all(self.fd, local + m.name + struct.pack("<HHQQ", 1, 16, m.size, m.size), m.local)
            central.append(
                struct.pack(
                    "<IHHHHHHIIIHHHHHII",
                    0x02014B50,
                    45,
                    45,
                    0,
                    0,
                    0,
                    0x21,
                    crc,
                    0xFFFFFFFF,
                    0xFFFFFFFF,
                    len(m.name),
                    28,
                    0,
                    0,
                    0,
                    0o644 << 16,
                    0xFFFFFFFF,
                )  # fmt: skip
                + m.name
                + struct.pack("<HHQQQ", 1, 24, m.size, m.size, m.local)
            )
        cd = b"".join(central)
        k = len(central)
        z64 = struct.pack("<IQHHIIQQQQ", 0x06064B50, 44, 45, 45, 0, 0, k, k, len(cd), self.end)
        loc = struct.pack("<IIQI", 0x07064B50, 0, self.end + len(cd), 1)
        eocd = struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, 0xFFFF, 0xFFFF, 0xFFFFFFFF, 0xFFFFFFFF, 0)
        tail = cd + z64 + loc + eocd
        pwrite_all(self.fd, tail, self.end)
        self._writer.shutdown()
        self._crc.shutdown()
        self.output.commit()
        self.fd = -1

    def abort(self) -> None:
        try:
            self._drain()  # no write may land after the file is gone
        except BaseException:
            pass  # the error that brought us here is the one to report
        self._writer.shutdown()
        self._crc.shutdown()
        self.output.abort()
        self.fd = -1

    def __enter__(self) -> NpzWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            try:
                self.close()
            except OSError as err:
                self.abort()
                if not write_failure(err):
                    raise
                raise self.output.error(err) from None
            return
        self.abort()
        if isinstance(exc, OSError) and write_failure(exc):  # a full disk here or in a store beside it
            raise self.output.error(exc) from None
