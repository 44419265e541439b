"""COBS decoding and CRC-32 checking of many equal-length frames in one C call.

The decoder's numpy path (:func:`accelnav.link.codec.cobs_decode_rows`
and ``crc_rows``) walks every frame's COBS chain in lockstep and checks the
CRC of long frames through ``zlib.crc32`` one frame at a time; for an hour of
1 kHz compact telemetry (140 000 frames of 177 bytes) those two cost about a
third of the whole decode. This kernel does the same per frame in C, reading
the frames where they lie in the received buffer (no gathered copy), and
returns the same three arrays: the decoded bytes, whether the COBS chain was
well formed, and whether the CRC matched.

The C is csrc/acnwire.c (package data). It is compiled into the wheel
(host/native/kernels.py, named in setup.py), so an installed package decodes
fast with no C compiler; a source checkout whose C was edited since builds it
on first use with the project's cffi builder
(:func:`accelnav.native.cbuild.build_module`, cached on disk). Without
either, :func:`wire_lib` returns None and the decoder keeps its numpy path,
so reading logs never needs a compiler. The tests hold both paths to each
other on random, damaged and truncated frames, and the C's CRC table to
zlib.
"""

from __future__ import annotations

import threading

import numpy as np

from accelnav.native.cbuild import STRICT_FLAGS
from accelnav.native.kernels import WIRE, build, prebuilt
from accelnav.resources import package_dir

CSRC = package_dir("accelnav.link") / "csrc"  # package data: acnwire.c, acnwire.h

_lock = threading.Lock()
_built: list = []  # [module or None] once tried


def _prebuilt():
    """The kernel compiled with the package (host/native/kernels.py), if it was built from this very C."""
    return prebuilt(WIRE, CSRC)


def _builder_built():
    """The kernel built from csrc/ by the project's cffi builder; None where that cannot be done (no C
    compiler)."""
    return build(WIRE, CSRC, STRICT_FLAGS, "acn_wire", required=False)


def wire_lib():
    """The kernel module: the package's own build, else built on first use; None without either."""
    with _lock:
        if not _built:
            _built.append(_prebuilt() or _builder_built())
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
