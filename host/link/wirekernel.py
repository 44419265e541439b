"""COBS decoding and CRC-32 checking of many equal-length frames in one C call.

The decoder's numpy path (:func:`accelnav.link.telemetry._cobs_decode_rows`
and ``_crc_rows``) walks every frame's COBS chain in lockstep and checks the
CRC of long frames through ``zlib.crc32`` one frame at a time; for an hour of
1 kHz compact telemetry (140 000 frames of 177 bytes) those two cost about a
third of the whole decode. This kernel does the same per frame in C, reading
the frames where they lie in the received buffer (no gathered copy), and
returns the same three arrays: the decoded bytes, whether the COBS chain was
well formed, and whether the CRC matched.

It is compiled on first use with the project's cffi builder
(:func:`accelnav.codegen.cbuild.build_module`, cached on disk); where no C
compiler is found :func:`wire_lib` returns None and the decoder keeps its
numpy path, so reading logs never needs a compiler. The tests hold both
paths to each other on random, damaged and truncated frames.
"""

from __future__ import annotations

import threading
import zlib

import numpy as np


def _crc_table() -> list[int]:
    """The 256 entries of the reflected CRC-32 table (polynomial 0xEDB88320, zlib's), checked against zlib."""
    table = []
    for b in range(256):
        c = b
        for _ in range(8):
            c = (c >> 1) ^ (0xEDB88320 if c & 1 else 0)
        table.append(c)
    crc = 0xFFFFFFFF
    for b in b"accelnav":
        crc = table[(crc ^ b) & 0xFF] ^ (crc >> 8)
    if crc ^ 0xFFFFFFFF != zlib.crc32(b"accelnav"):
        raise AssertionError("CRC-32 table does not reproduce zlib")
    return table


def _source() -> str:
    rows = [", ".join(f"0x{v:08x}u" for v in _crc_table()[i : i + 6]) for i in range(0, 256, 6)]
    table = ",\n    ".join(rows)
    return f"""#include <stdint.h>
#include <string.h>

static const uint32_t acnw_table[256] = {{
    {table}
}};

/* Frame i is the L bytes at buf + start[i] (no delimiter, no zero byte inside). Its COBS
 * decoding (L - 1 bytes) goes to dec + i * (L - 1); ok[i] = 1 when every code byte points
 * inside the frame or exactly at its end (a code of 0xFF always points past it: frames are
 * shorter than 254 bytes); crc[i] = 1 when the CRC-32 of the first L - 5 decoded bytes equals
 * the last four (little-endian). A chain that breaks leaves the zeros placed so far. */
void acnw_decode(const uint8_t *buf, const int64_t *start, int64_t n, int64_t L, uint8_t *dec, uint8_t *ok,
                 uint8_t *crc)
{{
    int64_t i, k, m = L - 1;
    for (i = 0; i < n; ++i) {{
        const uint8_t *f = buf + start[i];
        uint8_t *d = dec + i * m;
        int64_t pos = 0;
        uint32_t c = 0xFFFFFFFFu, want;
        uint8_t good = 1;
        memcpy(d, f + 1, (size_t)m);
        for (;;) {{
            int64_t nxt = pos + f[pos];
            if (f[pos] == 0u || nxt > L) {{
                good = 0;
                break;
            }}
            if (nxt == L) break;
            d[nxt - 1] = 0;
            pos = nxt;
        }}
        ok[i] = good;
        for (k = 0; k < m - 4; ++k) c = acnw_table[(c ^ d[k]) & 0xFFu] ^ (c >> 8);
        want = (uint32_t)d[m - 4] | (uint32_t)d[m - 3] << 8 | (uint32_t)d[m - 2] << 16 | (uint32_t)d[m - 1] << 24;
        crc[i] = (uint8_t)((c ^ 0xFFFFFFFFu) == want);
    }}
}}
"""


_CDEF = (
    "void acnw_decode(const uint8_t *buf, const int64_t *start, int64_t n, int64_t L, uint8_t *dec, uint8_t *ok,"
    " uint8_t *crc);\n"
)

_lock = threading.Lock()
_built: list = []  # [module or None] once tried


def wire_lib():
    """The compiled kernel module, or None when it cannot be built here (no C compiler)."""
    with _lock:
        if not _built:
            from accelnav.codegen.cbuild import BuildError, build_module

            try:
                _built.append(build_module("acn_wire", _CDEF, {"acnwire.c": _source()}, main="acnwire.c"))
            except BuildError:
                _built.append(None)
        return _built[0]


def decode_frames(mod, buf, starts: np.ndarray, L: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((n, L - 1) decoded bytes, (n,) COBS chain well formed, (n,) CRC matched) of the L-byte frames at
    ``starts`` (int64) in ``buf`` (bytes or a uint8 array), through the kernel module ``mod``."""
    starts = np.ascontiguousarray(starts, np.int64)
    n = len(starts)
    if n and (int(starts.min()) < 0 or int(starts.max()) + L > len(buf)):
        raise ValueError("a frame runs past the buffer")
    dec = np.empty((n, L - 1), np.uint8)
    ok = np.empty(n, np.uint8)
    crc = np.empty(n, np.uint8)
    ffi = mod.ffi
    if n:
        mod.lib.acnw_decode(
            ffi.from_buffer("uint8_t[]", buf),
            ffi.from_buffer("int64_t[]", starts),
            n,
            L,
            ffi.from_buffer("uint8_t[]", dec, require_writable=True),
            ffi.from_buffer("uint8_t[]", ok, require_writable=True),
            ffi.from_buffer("uint8_t[]", crc, require_writable=True),
        )
    return dec, ok.view(bool), crc.view(bool)
