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

import json
import os
import struct
import time
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

MAGIC = b"ACNLOG1\n"
CHUNK = b"ACNK"
FORMAT = "accelnav-log/1"
_CHUNK_HEAD = struct.Struct("<4sIQI")  # magic, len, t_ns, crc
MAX_CHUNK = 1 << 24


def is_log(path: str | Path) -> bool:
    """Whether ``path`` is a recorder log (it starts with MAGIC); False for a file that cannot be read."""
    try:
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
        self.path = Path(path)
        self.flush_ns = int(flush_s * 1e9)
        self.fsync_ns = None if fsync_s is None else int(fsync_s * 1e9)
        self.max_chunk = max_chunk
        self.clock = clock
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | (os.O_TRUNC if overwrite else os.O_EXCL)
        self.fd = os.open(self.path, flags, 0o644)
        head = json.dumps({"format": FORMAT, **meta}, sort_keys=True).encode()
        os.write(self.fd, MAGIC + struct.pack("<I", len(head)) + head + struct.pack("<I", zlib.crc32(head)))
        os.fsync(self.fd)
        self._buf = bytearray()
        self._t_first = 0
        self._last_sync = clock()
        self.chunks = 0
        self.bytes = 0

    def append(self, data: bytes, t_ns: int | None = None) -> None:
        """Add received bytes; writes a chunk when the oldest buffered byte is flush_s old."""
        now = self.clock() if t_ns is None else t_ns
        self.poll(now)  # what is due goes out first: a chunk holds bytes of at most flush_s
        if data:
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
        if self.fsync_ns is not None and now - self._last_sync >= self.fsync_ns:
            os.fsync(self.fd)
            self._last_sync = now

    def flush(self) -> None:
        if not self._buf:
            return
        body = bytes(self._buf)
        lt = struct.pack("<IQ", len(body), self._t_first)
        crc = zlib.crc32(body, zlib.crc32(lt))
        os.write(self.fd, _CHUNK_HEAD.pack(CHUNK, len(body), self._t_first, crc) + body)
        self.chunks += 1
        self.bytes += len(body)
        self._buf.clear()

    def close(self) -> None:
        if self.fd < 0:
            return
        self.flush()
        os.fsync(self.fd)
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
    if not buf.startswith(MAGIC):
        raise LogError(f"{source}: not an accelnav log (it does not start with {MAGIC!r})")
    if len(buf) < len(MAGIC) + 4:
        raise LogError(f"{source}: the header is cut short")
    (n,) = struct.unpack_from("<I", buf, len(MAGIC))
    start = len(MAGIC) + 4
    if len(buf) < start + n + 4:
        raise LogError(f"{source}: the header is cut short")
    head = buf[start : start + n]
    (crc,) = struct.unpack_from("<I", buf, start + n)
    if zlib.crc32(head) != crc:
        raise LogError(f"{source}: the header is damaged (CRC)")
    try:
        meta = json.loads(head)
    except ValueError:  # JSONDecodeError and UnicodeDecodeError alike
        raise LogError(f"{source}: the header is not JSON") from None
    fmt = meta.get("format") if isinstance(meta, dict) else None
    if fmt != FORMAT:
        raise LogError(f"{source}: format {repr(fmt)[:60]}; accepted: {FORMAT!r}")
    return meta, start + n + 4


def _chunks(buf: bytes, pos: int) -> Iterator[tuple[str, int, int, bytes]]:
    """('ok', pos, t_ns, data) per good chunk, ('skip', pos, n, b'') per damaged run, ('torn', pos, n, b'')."""
    end = len(buf)
    while pos < end:
        if end - pos < _CHUNK_HEAD.size:
            yield ("torn", pos, end - pos, b"")
            return
        magic, n, t_ns, crc = _CHUNK_HEAD.unpack_from(buf, pos)
        body_at = pos + _CHUNK_HEAD.size
        if magic == CHUNK and n <= MAX_CHUNK:
            if body_at + n > end:
                yield ("torn", pos, end - pos, b"")
                return
            body = buf[body_at : body_at + n]
            if zlib.crc32(body, zlib.crc32(buf[pos + 4 : pos + 16])) == crc:
                yield ("ok", pos, t_ns, body)
                pos = body_at + n
                continue
        nxt = buf.find(CHUNK, pos + 1)
        if nxt < 0:
            yield ("torn", pos, end - pos, b"")
            return
        yield ("skip", pos, nxt - pos, b"")
        pos = nxt


def read_log(path: str | Path) -> LogContents:
    """Every readable chunk of a log (a torn or damaged tail is reported, not raised)."""
    path = Path(path)
    try:
        buf = path.read_bytes()
    except FileNotFoundError:
        raise LogError(f"{path}: no such file") from None
    meta, pos = read_header(buf, str(path))
    times, data, damaged, torn = [], [], 0, 0
    for kind, _pos, a, body in _chunks(buf, pos):
        if kind == "ok":
            times.append(a)
            data.append(body)
        elif kind == "skip":
            damaged += a
        else:
            torn += a
    return LogContents(meta, times, data, damaged, torn)
