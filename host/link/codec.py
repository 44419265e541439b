"""The frame codec: COBS + CRC-32 frames, one at a time and vectorised over many of one length.

A frame on the wire is COBS(payload || crc32 LE) || 0x00, its payload a record of the manifest's
dtype. The vectorised kernels work on (n, L) arrays of frames of one length: COBS walks every
frame's code chain at once, and the CRC of a fixed-length message is affine in its bytes
(crc(m) = c0 ^ XOR_j T_j[m_j]), so it is a table gather per position.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from .manifest import Manifest

CHUNK_ROWS = 16384  # frames per vectorised block (bounds the temporaries to a few MB)


def cobs_encode(data: bytes) -> bytes:
    """COBS as the firmware does it (firmware/src/cobs.c); no delimiter."""
    out = bytearray([0])
    code_at, code = 0, 1
    for b in data:
        if b == 0:
            out[code_at] = code
            code_at, code = len(out), 1
            out.append(0)
            continue
        out.append(b)
        code += 1
        if code == 0xFF:
            out[code_at] = code
            code_at, code = len(out), 1
            out.append(0)
    out[code_at] = code
    return bytes(out)


def cobs_decode(data: bytes) -> bytes | None:
    """Inverse of :func:`cobs_encode`; None if malformed."""
    out = bytearray()
    r, n = 0, len(data)
    while r < n:
        code = data[r]
        r += 1
        if code == 0 or r + code - 1 > n:
            return None
        out += data[r : r + code - 1]
        r += code - 1
        if code != 0xFF and r < n:
            out.append(0)
    return bytes(out)


def frame(payload: bytes) -> bytes:
    """One frame on the wire: COBS(payload || crc32 LE) || 0x00."""
    return cobs_encode(payload + struct.pack("<I", zlib.crc32(payload))) + b"\0"


def pack_payload(man: Manifest, name: str, values: dict) -> bytes:
    """The payload of one frame ``name`` from {field: value} (missing fields are 0)."""
    fr = man.frames[name]
    rec = np.zeros((), dtype=man.dtypes[name])
    rec["type"] = fr["type"]
    for k, v in values.items():
        rec[k] = v
    return rec.tobytes()


def encode_command(man: Manifest, name: str, **args) -> bytes:
    """A command frame: ``encode_command(man, "decimate", factor=10)``."""
    key = f"cmd_{name}"
    if key not in man.frames:
        raise ValueError(
            f"unknown command {name!r}; accepted: {', '.join(k[4:] for k in man.frames if k.startswith('cmd_'))}"
        )
    return frame(pack_payload(man, key, args))


def encode_frames(man: Manifest, name: str, records: np.ndarray) -> bytes:
    """Many frames of one type from a structured array of ``man.dtypes[name]`` (vectorised)."""
    dt = man.dtypes[name]
    recs = np.ascontiguousarray(records, dtype=dt).copy()
    recs["type"] = man.frames[name]["type"]
    n, size = len(recs), dt.itemsize
    raw = np.empty((n, size + 4), np.uint8)
    raw[:, :size] = recs.view(np.uint8).reshape(n, size)
    raw[:, size:] = crc_rows(raw[:, :size]).view(np.uint8).reshape(n, 4)
    return _cobs_encode_rows(raw).tobytes()


def encode_stimulus(man: Manifest, flags=None, **raw) -> bytes:
    """Stimulus frames for N samples: ``encode_stimulus(man, code=(N, n_axes) ints)`` or ``t1=..., t2=...``."""
    first = np.asarray(next(iter(raw.values())))
    n = first.shape[0]
    rec = np.zeros(n, dtype=man.dtypes["stimulus"])
    rec["flags"] = 0 if flags is None else np.asarray(flags)
    for key in man.raw_fields():
        vals = np.asarray(raw[key])
        for j, ax in enumerate(man.axes):
            rec[f"{ax}.{key}"] = vals[:, j]
    return encode_frames(man, "stimulus", rec)


_CRC_TABLE_CACHE: dict[int, tuple[np.ndarray, int]] = {}


def _crc_tables(m: int) -> tuple[np.ndarray, int]:
    """Per-position tables T (m, 256) and c0 with crc32(msg) = c0 ^ XOR_j T[j, msg[j]] for m-byte messages."""
    hit = _CRC_TABLE_CACHE.get(m)
    if hit is not None:
        return hit
    c0 = zlib.crc32(bytes(m))
    T = np.zeros((m, 256), np.uint32)
    basis = np.zeros((m, 8), np.uint32)
    for j in range(m):
        for k in range(8):
            msg = bytearray(m)
            msg[j] = 1 << k
            basis[j, k] = zlib.crc32(bytes(msg)) ^ c0
    b = np.arange(256)
    for k in range(8):
        T ^= np.where((b >> k) & 1, basis[:, k : k + 1], 0).astype(np.uint32)
    _CRC_TABLE_CACHE[m] = (T, c0)
    return T, c0


def crc_rows(rows: np.ndarray) -> np.ndarray:
    """zlib.crc32 of every row of a (n, m) uint8 array, as (n,) uint32. Long rows (the compact mode's
    block frames) go through zlib row by row, which beats the table gathers there (2x at 177 bytes)."""
    n, m = rows.shape
    if m >= 64:
        buf = memoryview(np.ascontiguousarray(rows).tobytes())
        return np.fromiter((zlib.crc32(buf[i : i + m]) for i in range(0, n * m, m)), np.uint32, n)
    T, c0 = _crc_tables(m)
    out = np.empty(n, np.uint32)
    cols = np.arange(m)
    for a in range(0, n, CHUNK_ROWS):
        blk = rows[a : a + CHUNK_ROWS]
        out[a : a + CHUNK_ROWS] = np.bitwise_xor.reduce(T[cols, blk], axis=1) ^ np.uint32(c0)
    return out


def _cobs_encode_rows(raw: np.ndarray) -> np.ndarray:
    """COBS-encode every row (each < 254 bytes) and append the delimiter: (n, m) -> (n, m + 2)."""
    n, m = raw.shape
    out = np.zeros((n, m + 2), np.uint8)
    out[:, 1 : m + 1] = raw
    # each zero (and the end) holds the distance to the next zero (or the end) + ...: code at a
    # zero position p (in out coordinates, the leading code byte being a virtual zero at 0) is
    # the distance to the next zero or to position m + 1
    z = out[:, : m + 1] == 0
    z[:, 0] = True
    pos = np.where(z, np.arange(m + 1), m + 1)
    nxt = np.minimum.accumulate(pos[:, ::-1], axis=1)[:, ::-1]  # next zero at or after each index
    nxt_after = np.empty_like(nxt)
    nxt_after[:, :-1] = nxt[:, 1:]
    nxt_after[:, -1] = m + 1
    codes = (nxt_after - np.arange(m + 1)).astype(np.uint8)
    out[:, : m + 1] = np.where(z, codes, out[:, : m + 1])
    return out


def cobs_decode_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COBS-decode (n, L) rows of one length (no delimiter): ((n, L - 1) bytes, (n,) valid)."""
    n, L = rows.shape
    rows = np.ascontiguousarray(rows)
    flat = rows.ravel()
    dec = rows[:, 1:].copy()
    dflat = dec.ravel()
    valid = np.ones(n, bool)
    idx = np.arange(n, dtype=np.int64)
    pos = np.zeros(n, np.int64)
    while idx.size:  # one step along every frame's chain of code bytes at once
        nxt = pos + flat[idx * L + pos]
        valid[idx[nxt > L]] = False  # a code pointing past the end (0xFF too: frames are shorter than 254)
        go = nxt < L
        idx, pos = idx[go], nxt[go]
        dflat[idx * (L - 1) + pos - 1] = 0  # the code byte at pos stands for a zero
    return dec, valid
