"""The recorder's log: append-only, chunked, readable after a crash.

Format ``accelnav-log/1`` (all integers little-endian)::

    header  = b"ACNLOG1\\n" || u32 n || JSON (n bytes, UTF-8) || u32 crc32(JSON)
    chunk   = b"ACNK" || u32 len || u64 t_ns || u32 crc32(len || t_ns || bytes) || bytes (len)

The header JSON holds ``format``, the telemetry ``manifest`` the link was
decoded with, the ``model_toml`` text when known, and where and when it was
recorded. Each chunk holds the link's bytes exactly as received (frames,
garbage and all: the log is a replay of the link) and the host time of its
first byte, in ns since the epoch.

Durability: the writer keeps at most ``flush_s`` (0.1 s) of received bytes in
memory and hands every chunk to the operating system with one ``write()`` on
a file opened for appending, so a ``kill -9`` loses at most the last 0.1 s
(the kernel still writes what it was given); ``fsync_s`` bounds what a power
cut may take as well. A reader stops at a torn last chunk and resynchronises
at the next chunk magic after a damaged one, so a log stays readable.
"""

from __future__ import annotations

import errno
import json
import os
import stat
import struct
import time
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from accelnav.errors import UserError
from accelnav.fileio import OutputFile, check_input, output_target

MAGIC = b"ACNLOG1\n"
CHUNK = b"ACNK"
FORMAT = "accelnav-log/1"
_CHUNK_HEAD = struct.Struct("<4sIQI")  # magic, len, t_ns, crc
MAX_CHUNK = 1 << 24
MAX_HEADER = 1 << 24  # the header's JSON: a manifest and a model text, far below this


def is_log(path: str | Path) -> bool:
    """Whether ``path`` is a recorder log (it starts with MAGIC); False for a file that cannot be read and
    for anything but a regular file (a FIFO would block the read)."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return False
        with open(path, "rb") as fh:
            return fh.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


class LogError(ValueError):
    """A file that is not an accelnav log; ``str()`` is one line."""


class LogWriter:
    """``with LogWriter(path, meta) as log: log.append(data)``; see the module docstring."""

    def __init__(
        self,
        path: str | Path,
        meta: dict,
        *,
        flush_s: float = 0.1,
        fsync_s: float | None = 1.0,
        max_chunk: int = 1 << 16,
        overwrite: bool = False,
        clock=time.time_ns,
    ):
        self.path = Path(str(path))
        self.flush_ns = int(flush_s * 1e9)
        self.fsync_ns = None if fsync_s is None else int(fsync_s * 1e9)
        self.max_chunk = max_chunk
        self.clock = clock
        # the output rule (accelnav.fileio): a file appears with its whole header, replacing an existing log
        # only with ``overwrite``, and is then appended in place (a crash keeps what came); a FIFO or a
        # device is written through
        out = output_target(path, stdout="a recording goes to a file, a FIFO or a device")
        w = OutputFile(out)
        head = json.dumps({"format": FORMAT, **meta}, sort_keys=True).encode()
        view = memoryview(MAGIC + struct.pack("<I", len(head)) + head + struct.pack("<I", zlib.crc32(head)))
        try:
            while view:  # os.write here, as for the chunks: one place where this module meets the disk
                view = view[os.write(w.fd, view) :]
        except OSError as exc:
            w.abort()
            raise w.error(exc) from None
        try:
            w.commit(replace=overwrite, keep_open=True)
        except FileExistsError:
            raise FileExistsError(errno.EEXIST, "exists", str(path)) from None
        self.fd = w.fd
        self._sync = out.kind == "file"  # fsync: a pipe or a device has nothing to sync
        self._buf = bytearray()
        self.error: OSError | None = None  # the write that failed, if one did
        self._t_first = 0
        self._last_sync = clock()
        self.chunks = 0
        self.bytes = 0

    def append(self, data: bytes, t_ns: int | None = None) -> None:
        """Add received bytes; writes a chunk when the oldest buffered byte is flush_s old."""
        now = self.clock() if t_ns is None else t_ns
        self.poll(now)  # what is due goes out first: a chunk holds bytes of at most flush_s
        if data and self.error is None:
            if not self._buf:
                self._t_first = now
            self._buf += data
            if len(self._buf) >= self.max_chunk:
                self.flush()

    def poll(self, now: int | None = None) -> None:
        """Call at least every flush_s even without data: writes what is due."""
        now = self.clock() if now is None else now
        if self._buf and (now - self._t_first >= self.flush_ns or len(self._buf) >= self.max_chunk):
            self.flush()
        if self.fsync_ns is not None and now - self._last_sync >= self.fsync_ns and self.error is None:
            if self._sync:
                os.fsync(self.fd)
            self._last_sync = now

    def flush(self) -> None:
        if not self._buf or self.error is not None:
            return
        body = bytes(self._buf)
        lt = struct.pack("<IQ", len(body), self._t_first)
        crc = zlib.crc32(body, zlib.crc32(lt))
        self._write(_CHUNK_HEAD.pack(CHUNK, len(body), self._t_first, crc) + body)
        self.chunks += 1
        self.bytes += len(body)
        self._buf.clear()

    def _write(self, data: bytes) -> None:
        """All of ``data`` (a short write is continued). The first OSError (a full disk) is kept in
        ``error`` and raised once; from then on the writer drops data and closes quietly, and the log
        holds what was written before it (a reader takes a torn last chunk as the end)."""
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self.fd, view) :]
        except OSError as exc:
            self.error = exc
            self._buf.clear()
            raise

    def close(self) -> None:
        if self.fd < 0:
            return
        try:
            self.flush()
            if self.error is None and self._sync:
                os.fsync(self.fd)
        finally:
            os.close(self.fd)
            self.fd = -1

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass
class LogContents:
    meta: dict
    times: list[int]  # per chunk: host time of its first byte, ns
    data: list[bytes]  # per chunk: the link's bytes
    damaged_bytes: int  # bytes skipped (damaged chunks)
    torn_bytes: int  # bytes of an unfinished last chunk

    @property
    def nbytes(self) -> int:
        return sum(len(d) for d in self.data)


def read_header(buf: bytes, source: str) -> tuple[dict, int]:
    """(meta, offset of the first chunk) from the start of a log; a LogError for anything malformed."""
    if not buf.startswith(MAGIC):
        if MAGIC.startswith(bytes(buf)) and buf:
            raise LogError(f"{source}: the header is cut short")
        raise LogError(f"{source}: not an accelnav log (it does not start with {MAGIC!r})")
    if len(buf) < len(MAGIC) + 4:
        raise LogError(f"{source}: the header is cut short")
    (n,) = struct.unpack_from("<I", buf, len(MAGIC))
    if n > MAX_HEADER:
        raise LogError(f"{source}: the header declares {n} bytes; accepted: at most {MAX_HEADER} (damaged)")
    start = len(MAGIC) + 4
    if len(buf) < start + n + 4:
        raise LogError(f"{source}: the header is cut short")
    head = bytes(buf[start : start + n])
    (crc,) = struct.unpack_from("<I", buf, start + n)
    if zlib.crc32(head) != crc:
        raise LogError(f"{source}: the header is damaged (CRC)")
    try:
        meta = json.loads(head)
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise LogError(f"{source}: the header is not UTF-8 JSON (damaged, or not written by accelnav)") from None
    if not isinstance(meta, dict):
        raise LogError(f"{source}: the header is JSON {type(meta).__name__}, not an object")
    if meta.get("format") != FORMAT:
        fmt = repr(meta.get("format"))
        raise LogError(f"{source}: format {fmt[:60]}; accepted: {FORMAT!r}")
    return meta, start + n + 4


_READ = 1 << 18  # bytes read from the file at a time


def _chunks(fh, pos: int) -> Iterator[tuple[str, int, int, bytes]]:
    """('ok', pos, t_ns, data) per good chunk, ('skip', pos, n, b'') per damaged run, ('torn', pos, n, b'').

    Reads ``fh`` from ``pos`` in pieces: memory is one chunk (MAX_CHUNK) and one piece, whatever the file.
    """
    buf = bytearray()
    at = pos  # the file offset of buf[0]
    eof = False

    def fill(k: int) -> None:
        nonlocal eof
        while len(buf) < k and not eof:
            data = fh.read(max(_READ, k - len(buf)))
            if data:
                buf.extend(data)
            else:
                eof = True

    while True:
        fill(_CHUNK_HEAD.size)
        if not buf:
            return
        if len(buf) < _CHUNK_HEAD.size:
            yield ("torn", at, len(buf), b"")
            return
        magic, n, t_ns, crc = _CHUNK_HEAD.unpack_from(buf, 0)
        if magic == CHUNK and n <= MAX_CHUNK:
            fill(_CHUNK_HEAD.size + n)
            if len(buf) < _CHUNK_HEAD.size + n:
                yield ("torn", at, len(buf), b"")
                return
            body = bytes(buf[_CHUNK_HEAD.size : _CHUNK_HEAD.size + n])
            if zlib.crc32(body, zlib.crc32(buf[4:16])) == crc:
                yield ("ok", at, t_ns, body)
                del buf[: _CHUNK_HEAD.size + n]
                at += _CHUNK_HEAD.size + n
                continue
        # damaged: resynchronise at the next chunk magic, holding only a piece of the run in memory
        start, skipped, search_from = at, 0, 1
        while True:
            k = buf.find(CHUNK, search_from)
            if k >= 0:
                del buf[:k]
                at += k
                yield ("skip", start, skipped + k, b"")
                break
            if eof:
                yield ("torn", start, skipped + len(buf), b"")
                return
            drop = len(buf) - (len(CHUNK) - 1)  # keep what could be the start of a magic
            del buf[:drop]
            at += drop
            skipped += drop
            search_from = 0
            fill(len(buf) + _READ)


class LogReader:
    """``with LogReader(path) as log: log.meta; for t_ns, data in log: ...``; the counts once iterated.

    Streams the file: memory is one chunk, whatever the log's size (``log info`` reads a log this way).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            check_input(self.path)  # a FIFO or a device is refused before it is read
        except UserError as exc:
            raise LogError(str(exc)) from None
        try:
            self._fh = open(self.path, "rb")
        except OSError as exc:
            raise LogError(f"{self.path}: cannot read: {exc.strerror or exc}") from None
        try:
            head = self._fh.read(len(MAGIC) + 4)
            if head.startswith(MAGIC) and len(head) == len(MAGIC) + 4:
                (n,) = struct.unpack_from("<I", head, len(MAGIC))
                head += self._fh.read(min(n, MAX_HEADER + 1) + 4)
            self.meta, pos = read_header(head, str(self.path))
        except BaseException:
            self._fh.close()
            raise
        self._pos = pos
        self.chunks = 0
        self.damaged_bytes = 0
        self.torn_bytes = 0

    def __iter__(self) -> Iterator[tuple[int, bytes]]:
        self._fh.seek(self._pos)
        for kind, _pos, a, body in _chunks(self._fh, self._pos):
            if kind == "ok":
                self.chunks += 1
                yield a, body
            elif kind == "skip":
                self.damaged_bytes += a
            else:
                self.torn_bytes += a

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> LogReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_log(path: str | Path) -> LogContents:
    """Every readable chunk of a log (a torn or damaged tail is reported, not raised)."""
    times, data = [], []
    with LogReader(path) as log:
        for t_ns, body in log:
            times.append(t_ns)
            data.append(body)
    return LogContents(log.meta, times, data, log.damaged_bytes, log.torn_bytes)
