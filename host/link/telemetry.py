"""Telemetry decoding: COBS + CRC-32 frames described by the manifest of :mod:`codegen.frames`.

A :class:`Decoder` takes the byte stream in chunks of any size (a serial read,
a log chunk, a whole file) and returns the frames completed in that chunk as
numpy structured arrays, one per frame type, whose field names are the
manifest's (``seq``, ``index``, ``x.code``, ``x.r`` ...). It resynchronises
at the next 0x00 after any garbage and counts what it refused.

Vectorised: every frame of a type has the same length on the wire (frames
are shorter than 254 bytes, so COBS adds exactly one byte), so a chunk is cut
at its zero bytes with one ``flatnonzero``, the candidate frames of each
length are gathered into a 2-D array, COBS-decoded by walking all their code
chains at once, and CRC-checked with per-position lookup tables (the CRC of
a fixed-length message is affine in its bytes: crc(m) = c0 ^ XOR_j T_j[m_j]).
Nothing loops over frames in Python.

:func:`decode_naive` is the straightforward frame-by-frame decode of the
same bytes (``bytes.split``, a Python COBS loop, ``zlib.crc32``,
``struct.unpack_from``): the benchmark's baseline and a second oracle in the
tests.

Lost frames: sample frames carry a 16-bit sequence number that the MCU
increments for every sample frame it means to send; the decoder counts the
gaps (modulo 2^16) between consecutive accepted sample frames. Losses of
65536 frames or more in one gap are undercounted by multiples of 65536; the
sample ``index`` (32 bits) shows them.
"""

from __future__ import annotations

import json
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CHUNK_ROWS = 16384  # frames per vectorised block (bounds the temporaries to a few MB)


# --------------------------------------------------------------------------
# Manifest


class Manifest:
    """The frame layout the MCU was built with (the JSON from codegen.frames)."""

    def __init__(self, data: dict):
        if data.get("protocol") != "accelnav-telemetry":
            raise ValueError("not an accelnav telemetry manifest (key 'protocol')")
        self.data = data
        self.axes: list[str] = list(data["axes"])
        self.input: str = data["input"]
        self.rate_hz: float = float(data["sample_rate_hz"])
        self.layout_hash: int = int(data["layout_hash"])
        self.model_sha256: str = data["model_sha256"]
        self.frames: dict[str, dict] = data["frames"]
        self.flags: dict[str, int] = data["flags"]
        self.axis_flags: dict[str, int] = data["axis_flags"]
        self.dtypes: dict[str, np.dtype] = {}
        self.by_type: dict[int, str] = {}
        for name, fr in self.frames.items():
            names, formats, offsets = ["type"], ["u1"], [0]
            for f in fr["fields"]:
                names.append(f["name"])
                formats.append(f["dtype"])
                offsets.append(f["offset"])
            self.dtypes[name] = np.dtype(
                {"names": names, "formats": formats, "offsets": offsets, "itemsize": fr["size"]}
            )
            self.by_type[fr["type"]] = name

    @classmethod
    def load(cls, path: str | Path) -> Manifest:
        return cls(json.loads(Path(path).read_text()))

    @classmethod
    def for_model(cls, model, form: str | None = None) -> Manifest:
        """Generate the manifest of ``model`` (runs the filter generator: a few seconds)."""
        from accelnav.codegen.emit_c import emit
        from accelnav.codegen.frames import emit_frames

        files = emit(model, form=form)
        frames = emit_frames(model, json.loads(files["accelnav.json"]))
        return cls(json.loads(frames["acnframe.json"]))

    def text(self) -> str:
        return json.dumps(self.data, sort_keys=True)

    def up(self) -> list[str]:
        return [n for n, f in self.frames.items() if f["direction"] == "up"]

    def field(self, frame: str, name: str) -> dict:
        for f in self.frames[frame]["fields"]:
            if f["name"] == name:
                return f
        raise KeyError(f"{frame}.{name}")

    def raw_fields(self) -> tuple[str, ...]:
        return ("t1", "t2") if self.input == "duty_cycle" else ("code",)


# --------------------------------------------------------------------------
# Framing primitives (Python side)


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
    raw[:, size:] = _crc_rows(raw[:, :size]).view(np.uint8).reshape(n, 4)
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


# --------------------------------------------------------------------------
# Vectorised kernels

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


def _crc_rows(rows: np.ndarray) -> np.ndarray:
    """zlib.crc32 of every row of a (n, m) uint8 array, as (n,) uint32."""
    n, m = rows.shape
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


def _cobs_decode_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


# --------------------------------------------------------------------------
# Decoder


@dataclass
class Stats:
    frames: dict[str, int] = field(default_factory=dict)
    lost: int = 0  # sample frames missing between accepted ones (seq gaps)
    bad_frames: int = 0  # delimited segments refused (length, COBS, type, CRC)
    crc_errors: int = 0  # of those: right length and COBS, wrong CRC
    garbage_bytes: int = 0  # bytes in refused segments
    bytes: int = 0

    def as_dict(self) -> dict:
        return {
            "frames": dict(self.frames),
            "lost": self.lost,
            "bad_frames": self.bad_frames,
            "crc_errors": self.crc_errors,
            "garbage_bytes": self.garbage_bytes,
            "bytes": self.bytes,
        }


@dataclass
class Batch:
    """Frames completed by one feed(): per up-frame type a structured array, in stream order."""

    frames: dict[str, np.ndarray]
    lost: int = 0

    def __getitem__(self, name: str) -> np.ndarray:
        return self.frames[name]


class Decoder:
    """Streaming, vectorised decoder of the frames in ``manifest``; see the module docstring."""

    def __init__(self, manifest: Manifest, directions: tuple[str, ...] = ("up",)):
        self.man = manifest
        self.names = [n for n, f in manifest.frames.items() if f["direction"] in directions]
        self.by_len: dict[int, list[str]] = {}
        for n in self.names:
            self.by_len.setdefault(manifest.frames[n]["size"] + 5, []).append(n)
        self.max_len = max(self.by_len)
        self._tail = b""
        self._overlong = False  # the tail exceeded every frame length: the segment is refused at its delimiter
        self._last_seq: int | None = None
        self.stats = Stats(frames={n: 0 for n in self.names})

    def feed(self, data: bytes) -> Batch:
        self.stats.bytes += len(data)
        buf = self._tail + bytes(data)
        arr = np.frombuffer(buf, np.uint8)
        zeros = np.flatnonzero(arr == 0)
        empty = {n: np.zeros(0, self.man.dtypes[n]) for n in self.names}
        if zeros.size == 0:
            self._keep_tail(buf)
            return Batch(empty)
        starts = np.empty(zeros.size, np.int64)
        starts[0] = 0
        starts[1:] = zeros[:-1] + 1
        lengths = zeros - starts
        if self._overlong:  # the first segment began before the kept tail
            lengths[0] = self.max_len + 1
            self._overlong = False
        self._keep_tail(buf[zeros[-1] + 1 :])

        keep = lengths > 0
        starts, lengths = starts[keep], lengths[keep]
        order_parts, name_parts, rec_parts = [], [], []
        accepted = np.zeros(starts.size, bool)
        for L, names in self.by_len.items():
            sel = np.flatnonzero(lengths == L)
            if sel.size == 0:
                continue
            rows = np.lib.stride_tricks.sliding_window_view(arr, L)[starts[sel]]  # one row copy per frame
            dec, ok = _cobs_decode_rows(rows)
            m = L - 1
            crc_ok = _crc_rows(dec[:, : m - 4]) == dec[:, m - 4 :].copy().view("<u4").ravel()
            type_ok = np.zeros(sel.size, bool)
            for n in names:
                type_ok |= dec[:, 0] == self.man.frames[n]["type"]
            self.stats.crc_errors += int(np.count_nonzero(ok & type_ok & ~crc_ok))
            good = ok & crc_ok & type_ok
            accepted[sel[good]] = True
            for n in names:
                g = good & (dec[:, 0] == self.man.frames[n]["type"])
                if g.any():
                    recs = np.ascontiguousarray(dec[g, : m - 4]).view(self.man.dtypes[n]).ravel()
                    order_parts.append(sel[g])
                    name_parts.append(n)
                    rec_parts.append(recs)
        refused = ~accepted
        self.stats.bad_frames += int(np.count_nonzero(refused))
        self.stats.garbage_bytes += int(lengths[refused].sum())
        out = dict(empty)
        for n, o, r in zip(name_parts, order_parts, rec_parts, strict=True):
            out[n] = r[np.argsort(o, kind="stable")] if o.size > 1 else r  # stream order
            self.stats.frames[n] += len(r)
        lost = self._count_lost(out.get("sample"))
        return Batch(out, lost)

    def _keep_tail(self, tail: bytes) -> None:
        if len(tail) > self.max_len:
            self.stats.garbage_bytes += len(tail) - self.max_len
            tail = tail[-self.max_len :]
            self._overlong = True
        self._tail = tail

    def _count_lost(self, samples: np.ndarray | None) -> int:
        if samples is None or len(samples) == 0:
            return 0
        seq = samples["seq"].astype(np.int64)
        gaps = (np.diff(seq) - 1) % 65536
        lost = int(gaps.sum())
        if self._last_seq is not None:
            lost += (int(seq[0]) - self._last_seq - 1) % 65536
        self._last_seq = int(seq[-1])
        self.stats.lost += lost
        return lost

    def finish(self) -> int:
        """End of stream: the bytes after the last delimiter are an unfinished frame; returns their count."""
        n = len(self._tail)
        if n:
            self.stats.bad_frames += 1
            self.stats.garbage_bytes += n
        self._tail = b""
        return n


def decode_all(man: Manifest, data: bytes) -> tuple[dict[str, np.ndarray], Stats]:
    """Decode a whole byte string at once."""
    d = Decoder(man)
    batch = d.feed(data)
    return batch.frames, d.stats


def decode_naive(man: Manifest, data: bytes) -> tuple[dict[str, list[tuple]], int]:
    """Frame-by-frame reference decode: ({frame: [field tuples]}, lost). The benchmark's baseline."""
    fmts = {}
    for name in man.up():
        fr = man.frames[name]
        parts = []
        for f in fr["fields"]:
            kind = f["kind"]
            parts.append(
                f"{kind[3:-1]}s"
                if kind.startswith("u8[")
                else {"u8": "B", "u16": "H", "u32": "I", "i32": "i", "i64": "q"}[kind]
            )
        fmts[fr["type"]] = (name, struct.Struct("<B" + "".join(parts)), fr["size"])
    out: dict[str, list[tuple]] = {n: [] for n in man.up()}
    last, lost = None, 0
    segments = data.split(b"\0")[:-1]  # the piece after the last delimiter is unfinished
    for seg in segments:
        if not seg:
            continue
        raw = cobs_decode(seg)
        if raw is None or len(raw) < 5:
            continue
        payload, crc = raw[:-4], int.from_bytes(raw[-4:], "little")
        if zlib.crc32(payload) != crc:
            continue
        kind = fmts.get(payload[0])
        if kind is None or len(payload) != kind[2]:
            continue
        rec = kind[1].unpack_from(payload)
        out[kind[0]].append(rec)
        if kind[0] == "sample":
            seq = rec[1]
            if last is not None:
                lost += (seq - last - 1) % 65536
            last = seq
    return out, lost


# --------------------------------------------------------------------------
# Values


def sample_columns(man: Manifest, samples: np.ndarray) -> dict[str, np.ndarray]:
    """Per-sample columns of sample frames in SI units: t, index, seq, flags, and per axis
    (n, n_axes) arrays of the raw input, r, u, a, eps and the axis flags."""
    n = len(samples)
    cols: dict[str, np.ndarray] = {
        "index": samples["index"].astype(np.int64),
        "seq": samples["seq"].astype(np.int64),
        "flags": samples["flags"].astype(np.int64),
        "t": samples["index"].astype(np.float64) / man.rate_hz,
    }
    for key in (*man.raw_fields(), "axis_flags", "r", "u", "a", "eps"):
        cols[key] = np.empty((n, len(man.axes)), np.int64 if key in ("code", "t1", "t2", "axis_flags") else np.float64)
    for j, ax in enumerate(man.axes):
        for key in man.raw_fields():
            cols[key][:, j] = samples[f"{ax}.{key}"]
        cols["axis_flags"][:, j] = samples[f"{ax}.flags"]
        for s, key in (("r", "r"), ("u", "u"), ("a", "a"), ("e", "eps")):
            frac = man.field("sample", f"{ax}.{s}")["frac"]
            cols[key][:, j] = np.ldexp(samples[f"{ax}.{s}"].astype(np.float64), -frac)
    return cols
