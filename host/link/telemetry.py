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
Nothing loops over frames in Python. Where a C compiler is found, the COBS
decoding and the CRC check of those frames go through one call of a small C
kernel instead (:mod:`accelnav.link.wirekernel`, the same results, several
times faster on long frames); the numpy path serves where none is.

:func:`decode_naive` is the straightforward frame-by-frame decode of the
same bytes (``bytes.split``, a Python COBS loop, ``zlib.crc32``,
``struct.unpack_from``): the benchmark's baseline and a second oracle in the
tests.

Compact mode (block and checkpoint frames, see :mod:`accelnav.codegen.frames`): the
decoder turns them into sample rows of the same dtype as the sample frame, their states
from the replay of the firmware's own filter (:mod:`accelnav.link.replay`, given to
:class:`Decoder`), every checkpoint held against the replay bit for bit, losses and
repeats counted in samples from the 32-bit index (:mod:`accelnav.link.compact`).

Lost and repeated frames: sample frames carry a 16-bit sequence number that
the MCU increments for every sample frame it means to send and the 32-bit
sample index; :class:`SampleOrder` drops a repeated or older frame (counted
in ``duplicates``, never delivered twice) and counts the frames missing in a
gap exactly, the index telling how many times seq wrapped.
"""

from __future__ import annotations

import json
import math
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .wirekernel import decode_frames

CHUNK_ROWS = 16384  # frames per vectorised block (bounds the temporaries to a few MB)
PROTOCOL = 3  # the manifest's protocol_version this decoder reads (codegen.frames.PROTOCOL_VERSION)


# --------------------------------------------------------------------------
# Manifest


class Manifest:
    """The frame layout the MCU was built with (the JSON from codegen.frames)."""

    def __init__(self, data: dict):
        if isinstance(data, dict) and data.get("protocol") == "accelnav-telemetry":
            if data.get("protocol_version") != PROTOCOL:
                raise ValueError(
                    f"telemetry protocol {data.get('protocol_version')!r}: this accelnav reads protocol {PROTOCOL} "
                    "only (regenerate the firmware and record again, or read it with the accelnav that recorded it)"
                )
        check_manifest(data)  # it may come from someone else's log: nothing unchecked reaches numpy or C
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
        from accelnav.codegen.generated import generate

        return cls(json.loads(generate(model, form=form)["acnframe.json"]))

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

    def checkpoints_sane(self, axis: np.ndarray, state: np.ndarray) -> np.ndarray:
        """Per checkpoint (``axis`` numbers, ``state`` images as rows of bytes) whether a firmware could
        have sent it: the axis exists and, for a gain-schedule axis, the row index in its image
        (``checkpoint_rows``: offset and rows per axis) lies inside the schedule's table."""
        axis = np.asarray(axis, np.int64)
        ok = axis < len(self.axes)
        for j, r in enumerate(self.data.get("checkpoint_rows") or ()):
            if r is None:
                continue
            at = np.flatnonzero(axis == j)
            if len(at):
                o = int(r["offset"])
                row = np.ascontiguousarray(np.asarray(state, np.uint8)[at, o : o + 4]).view("<u4").ravel()
                ok[at] = row < int(r["rows"])
        return ok

    def code_flags(self) -> list[int]:
        """The axis flags of a sample row for each 2-bit code of a compact block frame (0 updated,
        1 input refused: a rail, 2 no capture: a timeout, 3 missed by the board)."""
        af = self.axis_flags
        rail = 0 if self.input == "duty_cycle" else 1 << af["rail"]
        skip = 1 << af["skipped"]
        return [0, skip | rail, skip | (1 << af["timeout"]), skip | (1 << af["missed"])]


_NAME = re.compile(r"[^\x00-\x1f\x7f]{1,32}\Z")  # an axis name: it reaches field names and messages
_MAX_PAYLOAD = 249  # payload + CRC under 254 bytes: COBS adds exactly one byte (the decoder relies on it)
_NEEDED = {  # frame -> fields the decoder, the compact stream and the replay read (axis fields added below)
    "sample": ("seq", "index", "flags"),
    "ack": ("command", "index"),
    "cmd_stop": (),
    "block": ("index", "flags", "n", "run", "aflags"),
    "checkpoint": ("index", "flags", "axis", "run", "paused_at", "seq", "state"),
}


def _int(v, lo: int, hi: int) -> bool:
    return type(v) is int and lo <= v <= hi


def check_manifest(data) -> None:
    """Refuse, with a ValueError of one line, a manifest whose shape the decoder cannot trust.

    A log carries its manifest, so this is untrusted input: the types and ranges of every key the
    decoder, :mod:`accelnav.link.compact` and :mod:`accelnav.link.replay` read are checked here,
    axis names must be short printable names, field dtypes must be plain numbers inside their
    frame, and the frames those modules need must be there with the fields they read. What the
    generator writes always passes."""

    def bad(what: str) -> ValueError:
        return ValueError(f"not a usable accelnav telemetry manifest: {what}")

    if not isinstance(data, dict) or data.get("protocol") != "accelnav-telemetry":
        raise ValueError("not an accelnav telemetry manifest (key 'protocol')")
    axes = data.get("axes")
    if not isinstance(axes, list) or not 1 <= len(axes) <= 3:
        raise bad("'axes' is not a list of 1 to 3 names")
    # names only: what reaches C is the model's, and the replay takes a manifest only when it is the
    # one the model generates (accelnav.link.replay)
    if not all(isinstance(a, str) and _NAME.match(a) for a in axes) or len(set(axes)) < len(axes):
        raise bad(f"'axes' {str(axes)[:80]}: accepted: distinct names of 1 to 32 printable characters")
    if data.get("input") not in ("analog", "duty_cycle"):
        raise bad("'input' is not 'analog' or 'duty_cycle'")
    rate = data.get("sample_rate_hz")
    if type(rate) not in (int, float) or not (math.isfinite(rate) and rate > 0):
        raise bad("'sample_rate_hz' is not a positive number")
    if not _int(data.get("layout_hash"), 0, 2**32 - 1) or not isinstance(data.get("model_sha256"), str):
        raise bad("'layout_hash' or 'model_sha256' has the wrong type")
    for key, names, hi in (
        ("flags", ("reset", "resume", "replayed", "mismatch"), 15),
        ("axis_flags", ("rail", "skipped", "timeout", "missed"), 7),
    ):
        table = data.get(key)
        if not isinstance(table, dict) or not all(_int(v, 0, hi) for v in table.values()):
            raise bad(f"{key!r} is not a table of bit numbers 0..{hi}")
        if not all(k in table for k in names):
            raise bad(f"{key!r} lacks one of {', '.join(names)}")
    frames = data.get("frames")
    if not isinstance(frames, dict):
        raise bad("'frames' is not a table")
    types = set()
    for name, fr in frames.items():
        if not isinstance(fr, dict) or fr.get("direction") not in ("up", "down"):
            raise bad(f"frame {name!r} has no direction 'up' or 'down'")
        if not _int(fr.get("type"), 0, 255) or fr["type"] in types or not _int(fr.get("size"), 1, _MAX_PAYLOAD):
            raise bad(f"frame {name!r}: 'type' (a distinct byte) or 'size' (1..{_MAX_PAYLOAD}) is wrong")
        types.add(fr["type"])
        fields = fr.get("fields")
        if not isinstance(fields, list):
            raise bad(f"frame {name!r}: 'fields' is not a list")
        for f in fields:
            if not isinstance(f, dict):
                raise bad(f"frame {name!r}: a field is not a table")
            try:
                dt = np.dtype(f["dtype"]) if isinstance(f.get("dtype"), str) else None
            except (TypeError, ValueError, SyntaxError):
                dt = None
            if (
                dt is None
                or (dt.base.kind not in "ui")
                or not isinstance(f.get("name"), str)
                or not _int(f.get("offset"), 1, fr["size"] - dt.itemsize)
            ):
                raise bad(f"frame {name!r}: a field is not a plain integer inside the frame")
    compact = "block" in frames or "checkpoint" in frames
    for name, need in _NEEDED.items():
        if name in ("block", "checkpoint") and not compact:
            continue
        if name not in frames:
            raise bad(f"no {name!r} frame")
        have = {f["name"] for f in frames[name]["fields"]}
        if name in ("sample", "block"):
            need = need + tuple(f"{ax}.{k}" for ax in axes for k in _raw_fields(data["input"]))
        if name == "sample":
            need = need + tuple(f"{ax}.{k}" for ax in axes for k in ("flags", "r", "u", "a", "e"))
        missing = [n for n in need if n not in have]
        if missing:
            raise bad(f"frame {name!r} lacks {', '.join(missing)}")
    if compact:
        sb = data.get("state_bytes")
        if not _int(data.get("block_samples"), 1, 255) or not _int(data.get("checkpoint_samples"), 1, 2**24):
            raise bad("'block_samples' or 'checkpoint_samples' is out of range")
        if not isinstance(sb, list) or len(sb) != len(axes) or not all(_int(n, 1, 4096) for n in sb):
            raise bad("'state_bytes' is not one size per axis")
        shapes = {f["name"]: np.dtype(f["dtype"]).shape for f in frames["block"]["fields"]}
        slots = [n for n in _block_slots(axes, data["input"]) if shapes[n] != (data["block_samples"],)]
        ck = {f["name"]: np.dtype(f["dtype"]) for f in frames["checkpoint"]["fields"]}["state"]
        if slots or ck.shape != (max(sb),) or ck.base.itemsize != 1:
            raise bad("the block's slots or the checkpoint's state do not match 'block_samples' / 'state_bytes'")
        rows = data.get("checkpoint_rows")
        if rows is not None and (not isinstance(rows, list) or len(rows) != len(axes)):
            raise bad("'checkpoint_rows' is not one entry per axis")
        for r in rows or ():
            if r is not None and not (
                isinstance(r, dict) and _int(r.get("offset"), 0, 4092) and _int(r.get("rows"), 0, 2**32)
            ):
                raise bad("a 'checkpoint_rows' entry is not an offset and a row count")


def _block_slots(axes, kind: str) -> list[str]:
    """The block frame's per-slot arrays: the axis codes and each axis' raw inputs."""
    return ["aflags"] + [f"{ax}.{k}" for ax in axes for k in _raw_fields(kind)]


def _raw_fields(kind: str) -> tuple[str, ...]:
    return ("t1", "t2") if kind == "duty_cycle" else ("code",)


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
# Sample frame accounting

_WRAP = 1 << 16
_HALF = 1 << 15


class SampleOrder:
    """Exact accounting of sample frames from their ``seq`` (u16, one per frame the MCU meant to send)
    and ``index`` (u32, the sample index): which frames to deliver, how many were lost, how many repeated.

    A frame whose index is not past the last delivered one is a repeat or an older frame: dropped and
    counted in ``duplicates`` (never delivered twice), unless it is a firmware reset (the index restarts
    at 0, seq runs on): seq 1..32767 ahead, the index step not what the seq step back says (within 16
    frames, modulo 2^16), and either the reset flag or an index below what those seq steps take a fresh
    start to; for 16384 frames after it a frame from before that reset is a repeat too.

    For a frame with a later index the number of frames sent since the last delivered one is
    ``a + 65536 k`` with ``a`` the seq step modulo 2^16 and ``k`` chosen so that it is nearest to the
    index step divided by the decimation (the index step of the last one-frame step): gaps of any
    length are counted exactly as long as the decimation did not change and the MCU missed fewer than
    32768 frames' worth of samples inside the gap. After a frame flagged as the first after a filter
    reset, or a ``stop`` acknowledged inside the gap (the index runs on while stopped, seq does not),
    the seq step alone counts (k = 0); a stop of D frame periods whose ack was lost adds
    65536 round(D / 65536) lost frames (none below 32768).

    :meth:`step` is the rule frame by frame (:func:`decode_naive`); :meth:`run` applies it to a batch
    with numpy between the irregular frames (index not later, reset flag, stop), which it steps.
    """

    def __init__(self, reset_mask: int = 1 << 2, stop_command: int = 0x11):
        self.reset_mask = reset_mask
        self.stop_command = stop_command
        self.last_seq: int | None = None
        self.last_index: int | None = None
        self.decimation: int | None = None  # index step of the last one-frame step
        self.stops: list[int] = []  # indices of acknowledged stops not yet passed
        # after a reset: (seq of its first frame, seq, index and decimation of the last frame before it)
        self.before_reset: tuple[int, int, int, int] | None = None
        self._since_reset = 0
        self.mark: tuple[int, int] | None = None  # (seq, index) the next sample frame starts from
        self.lost = 0
        self.duplicates = 0

    def compact(self, seq: int, index: int) -> None:
        """A compact-mode checkpoint, in stream order with the sample frames: the firmware had sent sample
        frames up to ``seq`` (the next one's) when the compact stream reached ``index``. The first sample
        frame after it counts the frames it missed from there (a mode change whose first frames were lost),
        however long the compact stretch was."""
        if self.last_index is None or index > self.last_index:
            self.mark = (seq, index)

    def ack(self, command: int, index: int) -> None:
        """An ack frame, in stream order with the sample frames."""
        if command == self.stop_command:
            self.stops.append(index)

    def _paused(self, index: int) -> bool:
        last = self.last_index
        paused = any(last < s <= index for s in self.stops)
        self.stops = [s for s in self.stops if s > index]
        return paused

    def step(self, seq: int, index: int, flags: int) -> bool:
        """One accepted sample frame, in stream order: True to deliver it."""
        if self.mark is not None and index >= self.mark[1]:
            ms, mi = self.mark
            self.mark = None
            if self.last_index is None or mi > self.last_index:
                self.lost += (seq - ms) % _WRAP  # the frames sent between the compact stretch and this one
                self.last_seq, self.last_index = seq, index
                self.decimation, self.stops = None, []
                return True
        if self.last_seq is None:
            self.last_seq, self.last_index = seq, index
            return True
        a = (seq - self.last_seq) % _WRAP
        di = index - self.last_index
        ahead = 1 <= a < _HALF
        if di <= 0:
            # a firmware reset (the index started again at 0) if seq is ahead and the index no further than
            # those seq steps take it; otherwise a repeat of an earlier frame
            d = self.decimation or 1
            back = (-di / d - (_WRAP - a) + _HALF) % _WRAP - _HALF  # 0 for an older frame (modulo 2^16 frames)
            older = abs(back) <= 16
            if older or not (ahead and (flags & self.reset_mask or index < a * d)):
                self.duplicates += 1
                return False
            n = a
            self._reset(seq)
        elif self.before_reset and self._before(seq, index):
            self.duplicates += 1  # a repeat of a frame from before the last reset
            return False
        elif flags & self.reset_mask and ahead:
            n = a
            self._reset(seq)
        elif self._paused(index):
            n = a if a else _WRAP
        else:
            d = self.decimation
            k = max(0, round((di / d - a) / _WRAP)) if d else 0
            if a == 0:
                k = max(k, 1)
            n = a + _WRAP * k
            if a == 1:
                self.decimation = di
        self.lost += n - 1
        self.last_seq, self.last_index = seq, index
        if self.before_reset:
            self._since_reset += 1
            if self._since_reset > 16384:
                self.before_reset = None  # far enough into the new run: no repeats from before it any more
        return True

    def _reset(self, seq: int) -> None:
        self.before_reset = (seq, self.last_seq, self.last_index, self.decimation or 1)
        self._since_reset = 0
        self.decimation, self.stops = None, []

    def _before(self, seq: int, index: int) -> bool:
        """Is (seq, index) a frame from before the last reset (seq and index steps back agree)?"""
        _, ls, li, d = self.before_reset
        back = (ls - seq) % _WRAP
        return index <= li and back < _HALF and abs(((li - index) / d - back + _HALF) % _WRAP - _HALF) <= 16

    def run(self, seq, index, flags, stops: list[tuple[int, int]] = (), marks: list = ()) -> np.ndarray:
        """:meth:`step` over arrays (stream order), vectorised between irregular frames: the keep mask.
        ``stops``: (number of these sample frames before the ack in the stream, index) of stop acks;
        ``marks``: (number of sample frames before it, seq, index) of compact checkpoints (:meth:`compact`)."""
        n = len(seq)
        keep = np.ones(n, bool)
        marks = sorted(marks)
        if n == 0:
            for _, s in stops:
                self.stops.append(s)
            for _, ms, mi in marks:
                self.compact(ms, mi)
            return keep
        seq = seq.astype(np.int64)
        index = index.astype(np.int64)
        flags = flags.astype(np.int64)
        regular = np.zeros(n, bool)  # later index than the previous frame, no reset flag, no stop between
        regular[1:] = index[1:] > index[:-1]
        regular &= (flags & self.reset_mask) == 0
        prev = np.empty(n, np.int64)
        prev[0] = -1
        prev[1:] = index[:-1]
        for p, s in [(0, s) for s in self.stops] + list(stops):
            hit = (prev < s) & (s <= index)
            hit[:p] = False
            regular &= ~hit
        for p, _, _ in marks:
            if p < n:
                regular[p] = False
        pending = sorted(stops)
        irregular = np.flatnonzero(~regular)
        i = 0
        while i < n:
            while pending and pending[0][0] <= i:
                self.stops.append(pending.pop(0)[1])
            while marks and marks[0][0] <= i:
                self.compact(*marks.pop(0)[1:])
            keep[i] = self.step(int(seq[i]), int(index[i]), int(flags[i]))
            i += 1
            if not keep[i - 1] or i == n or self.before_reset:
                continue
            nb = irregular[np.searchsorted(irregular, i)] if irregular.size and irregular[-1] >= i else n
            if pending:
                nb = min(nb, max(pending[0][0], i))
            if marks:
                nb = min(nb, max(marks[0][0], i))
            if nb > i:
                self._regular(seq[i - 1 : nb], index[i - 1 : nb])
                i = nb
        for _, s in pending:
            self.stops.append(s)
        for _, ms, mi in marks:
            self.compact(ms, mi)
        return keep

    def _regular(self, s: np.ndarray, x: np.ndarray) -> None:
        """Frames s[1:], x[1:] after the delivered s[0], x[0], every index later than the one before."""
        a = np.diff(s) % _WRAP
        di = np.diff(x)
        one = a == 1
        pos = np.where(one, np.arange(a.size), -1)
        last_one = np.maximum.accumulate(pos)
        prev_one = np.empty_like(last_one)
        prev_one[0] = -1
        prev_one[1:] = last_one[:-1]
        d = np.where(prev_one >= 0, di[np.maximum(prev_one, 0)], self.decimation or 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(d > 0, np.rint((di / np.where(d > 0, d, 1) - a) / _WRAP), 0).astype(np.int64)
        k = np.maximum(k, 0)
        k = np.where(a == 0, np.maximum(k, 1), k)
        self.lost += int((a + _WRAP * k - 1).sum())
        if last_one[-1] >= 0:
            self.decimation = int(di[last_one[-1]])
        self.last_seq, self.last_index = int(s[-1]), int(x[-1])


# --------------------------------------------------------------------------
# Decoder


@dataclass
class Stats:
    frames: dict[str, int] = field(default_factory=dict)
    lost: int = 0  # sample frames missing between delivered ones
    duplicates: int = 0  # sample frames dropped as repeated or older than the last delivered one
    bad_frames: int = 0  # delimited segments refused (length, COBS, type, CRC, contents no firmware sends)
    crc_errors: int = 0  # of those: right length and COBS, wrong CRC
    garbage_bytes: int = 0  # bytes in refused segments
    bytes: int = 0
    # compact mode (block and checkpoint frames); lost and duplicates count its samples
    checkpoints: int = 0  # checkpoints the replay matched bit for bit
    mismatches: int = 0  # checkpoints the replay did not match (and stretches whose step verdicts differed)
    checkpoint_repeats: int = 0  # repeated or older checkpoints, ignored
    unreplayed: int = 0  # samples received without a replay to give them states (no model text)

    def as_dict(self) -> dict:
        return {
            "frames": dict(self.frames),
            "lost": self.lost,
            "duplicates": self.duplicates,
            "bad_frames": self.bad_frames,
            "crc_errors": self.crc_errors,
            "garbage_bytes": self.garbage_bytes,
            "bytes": self.bytes,
            "checkpoints": self.checkpoints,
            "mismatches": self.mismatches,
            "checkpoint_repeats": self.checkpoint_repeats,
            "unreplayed": self.unreplayed,
        }


@dataclass
class Batch:
    """Frames completed by one feed(): per up-frame type a structured array, in stream order."""

    frames: dict[str, np.ndarray]
    lost: int = 0

    def __getitem__(self, name: str) -> np.ndarray:
        return self.frames[name]


# the counts CompactStream keeps that the decoder's Stats carry under the same names
_COMPACT_COUNTS = ("lost", "duplicates", "mismatches", "checkpoints", "checkpoint_repeats", "unreplayed")


class Decoder:
    """Streaming, vectorised decoder of the frames in ``manifest``; see the module docstring."""

    def __init__(self, manifest: Manifest, directions: tuple[str, ...] = ("up",), replay=None, kernel: bool = True):
        """``replay``: an :class:`accelnav.link.replay.Replay` of the firmware's filter, which the compact
        mode's block frames need to become sample rows (:func:`replay_for` builds one from a model).
        ``kernel``: COBS and CRC through the C kernel of :mod:`accelnav.link.wirekernel` when it can be
        built here (else, or with False, the numpy path)."""
        self.man = manifest
        self._wire = None
        if kernel:
            from .wirekernel import wire_lib

            self._wire = wire_lib()
        self.names = [n for n, f in manifest.frames.items() if f["direction"] in directions]
        self.by_len: dict[int, list[str]] = {}
        for n in self.names:
            self.by_len.setdefault(manifest.frames[n]["size"] + 5, []).append(n)
        self.max_len = max(self.by_len)
        self._tail = b""
        self._overlong = False  # the tail exceeded every frame length: the segment is refused at its delimiter
        self.order = SampleOrder(1 << manifest.flags["reset"], manifest.frames["cmd_stop"]["type"])
        self.stats = Stats(frames={n: 0 for n in self.names})
        self.compact = None
        if "block" in self.names and "checkpoint" in self.names:
            from .compact import CompactStream

            self.compact = CompactStream(manifest, replay)

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
        if self._overlong:  # the first segment began before the kept tail: refused, counted at its full length
            self.stats.garbage_bytes += int(lengths[0]) - (self.max_len + 1)  # (the dropped part: _keep_tail)
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
            m = L - 1
            if self._wire is not None:
                dec, ok, crc_ok = decode_frames(self._wire, arr, starts[sel], L)
            else:
                rows = np.lib.stride_tricks.sliding_window_view(arr, L)[starts[sel]]  # one row copy per frame
                dec, ok = _cobs_decode_rows(rows)
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
                    sane = self._sane(n, recs)
                    if not sane.all():  # a right CRC on contents no firmware sends: refused as damaged
                        drop = np.flatnonzero(g)[~sane]
                        recs = recs[sane]
                        g[drop] = False
                        accepted[sel[drop]] = False
                    order_parts.append(sel[g])
                    name_parts.append(n)
                    rec_parts.append(recs)
        refused = ~accepted
        self.stats.bad_frames += int(np.count_nonzero(refused))
        self.stats.garbage_bytes += int(lengths[refused].sum())
        out = dict(empty)
        where = {}
        for n, o, r in zip(name_parts, order_parts, rec_parts, strict=True):
            k = np.argsort(o, kind="stable")
            out[n], where[n] = r[k], o[k]  # stream order
        lost = self._account(out, where)
        if self.compact is not None:
            lost += self._compact(out, where)
        for n in out:
            self.stats.frames[n] += len(out[n])
        return Batch(out, lost)

    def _account(self, out: dict, where: dict) -> int:
        """Drop repeated sample frames and count the lost ones (:class:`SampleOrder`)."""
        if "sample" not in out:
            return 0
        stops = []
        acks = out.get("ack")
        if acks is not None and len(acks):
            is_stop = acks["command"] == self.order.stop_command
            if is_stop.any():
                before = np.searchsorted(where.get("sample", np.zeros(0, np.int64)), where["ack"][is_stop])
                stops = list(zip(before.tolist(), acks["index"][is_stop].tolist(), strict=True))
        smp = out["sample"]
        marks = []
        cks = out.get("checkpoint")
        if cks is not None and len(cks):
            before = np.searchsorted(where.get("sample", np.zeros(0, np.int64)), where["checkpoint"])
            marks = list(zip(before.tolist(), cks["seq"].tolist(), cks["index"].tolist(), strict=True))
        lost0, dup0 = self.order.lost, self.order.duplicates
        keep = self.order.run(smp["seq"], smp["index"], smp["flags"], stops, marks)
        if not keep.all():
            out["sample"] = smp[keep]
            where["sample"] = where["sample"][keep]
        lost = self.order.lost - lost0
        self.stats.lost += lost
        self.stats.duplicates += self.order.duplicates - dup0
        return lost

    def _sane(self, name: str, recs: np.ndarray) -> np.ndarray:
        if name == "block":
            return (recs["n"] >= 1) & (recs["n"] <= self.compact.B)
        if name == "checkpoint":
            return self.man.checkpoints_sane(recs["axis"], recs["state"])
        return np.ones(len(recs), bool)

    def _compact(self, out: dict, where: dict) -> int:
        """Block and checkpoint frames -> sample rows (:class:`accelnav.link.compact.CompactStream`), merged
        with the state mode's sample frames in stream order."""
        c = self.compact
        e = np.zeros(0, np.int64)
        before = {k: getattr(c, k) for k in _COMPACT_COUNTS}
        dmg0 = c.damaged, c.damaged_bytes
        rows, rpos = c.feed(out["block"], where.get("block", e), out["checkpoint"], where.get("checkpoint", e))
        if len(out["sample"]):  # held rows before a state-mode frame go out before it, never after
            early, epos = c.release_before(int(where["sample"][-1]))
            if len(early):
                k = np.argsort(np.r_[rpos, epos], kind="stable")
                rows, rpos = np.concatenate([rows, early])[k], np.r_[rpos, epos][k]
        self.stats.bad_frames += c.damaged - dmg0[0]
        self.stats.garbage_bytes += c.damaged_bytes - dmg0[1]
        if len(rows):
            if len(out["sample"]):
                spos = where["sample"]
                allpos = np.r_[spos, rpos]
                merged = np.concatenate([out["sample"], rows])
                out["sample"] = merged[np.argsort(allpos, kind="stable")]
            else:
                out["sample"] = rows
        for k, b in before.items():  # this batch's counts, added to the decoder's
            setattr(self.stats, k, getattr(self.stats, k) + getattr(c, k) - b)
        return c.lost - before["lost"]

    @property
    def received(self) -> int:
        """Samples received so far, delivered or not yet: sample rows out, plus the compact mode's rows held
        until the checkpoint closing their stretch and its samples with no replay (no model text). What a
        live view counts: rows wait up to a checkpoint interval (2.56 s at 100 Hz) before they go out."""
        n = self.stats.frames.get("sample", 0) + self.stats.unreplayed
        if self.compact is not None:
            n += len(self.compact.held[0])
        return n

    @property
    def mid_frame(self) -> bool:
        """Bytes of a frame whose delimiter has not come yet are held."""
        return bool(self._tail)

    def _keep_tail(self, tail: bytes) -> None:
        if len(tail) > self.max_len:
            self.stats.garbage_bytes += len(tail) - self.max_len
            tail = tail[-self.max_len :]
            self._overlong = True
        self._tail = tail

    @property
    def last_index(self) -> int | None:
        """The index of the last sample received in order (a sample frame, or a block's last sample)."""
        ends = [self.order.last_index]
        if self.compact is not None and self.compact.end is not None:
            ends.append(self.compact.end - 1)
        ends = [e for e in ends if e is not None]
        return max(ends) if ends else None

    def release(self) -> np.ndarray:
        """End of the stream: the compact mode's sample rows still waiting for the checkpoint that closes
        their stretch (replayed but never verified: the stream ended first); they count as delivered."""
        if self.compact is None:
            return np.zeros(0, self.man.dtypes["sample"])
        dmg0 = self.compact.damaged, self.compact.damaged_bytes
        rows = self.compact.release()
        self.stats.bad_frames += self.compact.damaged - dmg0[0]
        self.stats.garbage_bytes += self.compact.damaged_bytes - dmg0[1]
        self.stats.frames["sample"] += len(rows)
        return rows

    def finish(self) -> int:
        """End of stream: the bytes after the last delimiter are an unfinished frame; returns their count."""
        n = len(self._tail)
        if n:
            self.stats.bad_frames += 1
            self.stats.garbage_bytes += n
        self._tail = b""
        return n


def end_of_stream(dec: Decoder) -> np.ndarray:
    """A recording ends: the bytes after the last delimiter refused as an unfinished frame, the compact rows
    still waiting for a checkpoint released (and counted). The recorder and every reader of a log end a
    stream this one way, so that their counts (:func:`link_counts`) agree."""
    dec.finish()
    return dec.release()


def link_counts(stats: Stats | dict) -> dict:
    """The counts a user is shown for a link or a log: the one definition the recorder's summary and
    ``accelnav log info`` both print."""
    s = stats.as_dict() if isinstance(stats, Stats) else stats
    return {
        "samples": int(s["frames"].get("sample", 0)),
        "lost": s["lost"],
        "duplicates": s["duplicates"],
        "damaged_frames": s["bad_frames"],
        "crc_errors": s["crc_errors"],
        "garbage_bytes": s["garbage_bytes"],
        **(
            {k: s[k] for k in ("checkpoints", "mismatches", "checkpoint_repeats", "unreplayed")}
            if s["frames"].get("block")
            else {}
        ),
    }


def format_counts(c: dict) -> str:
    """:func:`link_counts` as the one line both the recorder and ``log info`` print."""
    text = (
        f"{c['samples']} samples, lost {c['lost']}, duplicates {c['duplicates']}, "
        f"damaged {c['damaged_frames']} frames (CRC errors {c['crc_errors']}, {c['garbage_bytes']} bytes)"
    )
    if "checkpoints" in c:
        text += f"; replay: {c['checkpoints']} checkpoints matched, {c['mismatches']} mismatches"
        if c["unreplayed"]:
            text += f", {c['unreplayed']} samples unreplayed (no model text)"
    return text


def replay_for(man: Manifest, model):
    """The replay of the firmware's filter (a Model or its TOML text) for ``man``'s compact frames;
    None when ``man`` has none or ``model`` is empty."""
    if "block" not in man.frames or not model:
        return None
    from .replay import Replay

    return Replay(man, model)


def decode_all(man: Manifest, data: bytes, replay=None) -> tuple[dict[str, np.ndarray], Stats]:
    """Decode a whole byte string at once (``replay``: see :class:`Decoder`)."""
    d = Decoder(man, replay=replay)
    frames = dict(d.feed(data).frames)
    rest = d.release()
    if len(rest):
        frames["sample"] = np.concatenate([frames["sample"], rest])
    return frames, d.stats


_STRUCT = {"u8": "B", "u16": "H", "u32": "I", "i32": "i", "i64": "q"}


def decode_naive(
    man: Manifest, data: bytes, counts: dict | None = None, replay=None
) -> tuple[dict[str, list[tuple]], int]:
    """Frame-by-frame reference decode: ({frame: [field tuples]}, lost). The benchmark's baseline.
    ``counts``, if given, receives ``lost`` and ``duplicates`` (and the compact mode's counts).
    Compact mode: block frames become sample rows (tuples like a sample frame's) sample by sample, the
    filter stepped one sample at a time (:func:`_naive_rows`)."""
    fmts = {}
    for name in man.up():
        fr = man.frames[name]
        parts = []
        for f in fr["fields"]:
            kind = f["kind"]
            if kind.startswith("u8["):
                parts.append(f"{kind[3:-1]}s")
            elif "[" in kind:
                parts.append(kind[kind.index("[") + 1 : -1] + _STRUCT[kind.split("[")[0]])
            else:
                parts.append(_STRUCT[kind])
        fmts[fr["type"]] = (name, struct.Struct("<B" + "".join(parts)), fr["size"])
    compact = []  # (frame number, name, record) of block and checkpoint frames
    out: dict[str, list[tuple]] = {n: [] for n in man.up()}
    order = SampleOrder(1 << man.flags["reset"], man.frames["cmd_stop"]["type"])
    names = {n: [f["name"] for f in man.frames[n]["fields"]] for n in ("sample", "ack")}
    i_seq, i_index, i_flags = (1 + names["sample"].index(k) for k in ("seq", "index", "flags"))
    i_cmd, i_aindex = (1 + names["ack"].index(k) for k in ("command", "index"))
    ck_names = [f["name"] for f in man.frames["checkpoint"]["fields"]] if "checkpoint" in man.frames else []
    i_cseq = 1 + ck_names.index("seq") if ck_names else None
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
        if kind[0] == "sample" and not order.step(rec[i_seq], rec[i_index], rec[i_flags]):
            continue
        if kind[0] == "ack":
            order.ack(rec[i_cmd], rec[i_aindex])
        if kind[0] == "checkpoint":
            order.compact(rec[i_cseq], rec[1])
        if kind[0] in ("block", "checkpoint"):
            if kind[0] == "block" and not 1 <= rec[3] <= man.data["block_samples"]:
                continue
            if kind[0] == "checkpoint" and not man.checkpoints_sane([rec[3]], [np.frombuffer(rec[-1], np.uint8)])[0]:
                continue
            compact.append((len(out["sample"]), kind[0], rec))
        out[kind[0]].append(rec)
    lost, dups, extra = order.lost, order.duplicates, {}
    if compact:
        rows, extra = _naive_rows(man, compact, replay)
        lost += extra["lost"]
        dups += extra["duplicates"]
        # a compact row whose block came after p sample frames goes before sample frame p (stream order)
        merged = [(i, 1, r) for i, r in enumerate(out["sample"])] + [(p, 0, r) for p, r in rows]
        out["sample"] = [r for _, _, r in sorted(merged, key=lambda x: (x[0], x[1]))]
    if counts is not None:
        counts.update(extra)
        counts.update(lost=lost, duplicates=dups)
    return out, lost


def _naive_rows(man: Manifest, frames: list, replay) -> tuple[list, dict]:
    """Sample rows from block and checkpoint frames, one sample at a time (the oracle of
    :class:`accelnav.link.compact.CompactStream`, which does the same by stretches)."""
    from .compact import CompactStream

    cs = CompactStream(man, replay)
    B, n_ax, raw = cs.B, len(man.axes), man.raw_fields()
    blocks = [r for _, k, r in frames if k == "block"]
    cks = [r for _, k, r in frames if k == "checkpoint"]
    kinds, ids, nb, nc = [], [], 0, 0
    for _, k, _ in frames:
        kinds.append(0 if k == "block" else 1)
        ids.append(nb if k == "block" else nc)
        nb, nc = (nb + 1, nc) if k == "block" else (nb, nc + 1)
    # block tuple: type, index, flags, n, run, 5 counters, aflags (bytes, or B values past 4 axes), then
    # per axis and raw field B values; checkpoint: type, index, flags, axis, run, paused_at, seq, state
    i_af = 10
    wide = not isinstance(blocks[0][i_af], bytes) if blocks else False
    base0 = i_af + B if wide else i_af + 1
    aflags = [r[i_af : i_af + B] if wide else r[i_af] for r in blocks]
    bpos = [p for p, k, _ in frames if k == "block"]
    states = [r[7] for r in cks]
    acc, breaks, events = cs.order(
        kinds, ids, [r[1] for r in blocks], [r[3] for r in blocks], [r[2] for r in blocks],
        [r[1] for r in cks], [r[2] for r in cks], [r[3] for r in cks], [np.frombuffer(s, np.uint8) for s in states],
        None, [r[4] for r in blocks], [r[4] for r in cks], [r[5] for r in cks],
    )  # fmt: skip
    if cs.defer is not None:  # the stream's last frame, never confirmed: damage
        cs.damaged += 1
    samples = []  # (block number, slot)
    for i in acc:
        samples += [(i, k) for k in range(blocks[i][3])]
    N = len(samples)
    ok = [True] * N
    mism = [False] * N
    x = [[None] * N for _ in range(n_ax)]
    breakset = set(breaks)
    for j in range(n_ax):
        nbj = cs.state_bytes[j]
        ev_at: dict[int, list] = {}
        for p, i, verify, sync in events[j]:
            ev_at.setdefault(p, []).append((i, verify, sync))
        st, since = None, []
        for p in range(N + 1):
            for i, verify, _ in ev_at.get(p, []):  # checkpoints closing the stretch that ends here
                if verify and st is not None:
                    if st == states[i][:nbj]:
                        cs.checkpoints += 1
                    else:
                        cs.mismatches += 1
                        for q in since:
                            mism[q] = True
            if p in breakset:
                st, since = None, []
            for i, _, sync in ev_at.get(p, []):
                if sync:
                    st, since = states[i][:nbj], []
            if p == N:
                break
            if st is None or replay is None:
                ok[p] = False
                continue
            b, k = samples[p]
            blk = blocks[b]
            code = (aflags[b][k] >> (2 * j)) & 3
            base = base0 + j * len(raw) * B
            in1 = np.array([blk[base + k]], np.uint32)
            in2 = np.array([blk[base + B + k]], np.uint32) if len(raw) > 1 else None
            one = np.zeros(1, man.dtypes["sample"])
            fin, nbad = replay.run(
                j, np.zeros(1, np.int64), np.ones(1, np.int64), np.frombuffer(st, np.uint8), [code], in1, in2, one
            )
            ax = man.axes[j]
            xs = [[int(one[f"{ax}.{c}"][0]) for c in "ruae"]]
            if nbad[0]:
                cs.mismatches += int(nbad[0])
                for q in [*since, p]:
                    mism[q] = True
            st = fin[0].tobytes()
            since.append(p)
            x[j][p] = xs[0]
    if replay is None:
        cs.unreplayed += N
    else:
        cs.lost += ok.count(False)
    per_code = man.code_flags()
    rows = []
    stype = man.frames["sample"]["type"]
    for p in range(N):
        if not ok[p] or replay is None:
            continue
        b, k = samples[p]
        blk = blocks[b]
        index = blk[1] + k
        fl = blk[2] if k == 0 else blk[2] & ~(cs.R | cs.X)
        fl |= cs.REPLAYED | (cs.MISMATCH if mism[p] else 0)
        row = [stype, index & 0xFFFF, index, fl, *blk[5:10]]
        for j in range(n_ax):
            base = base0 + j * len(raw) * B
            row.append(per_code[(aflags[b][k] >> (2 * j)) & 3])
            row += [blk[base + m * B + k] for m in range(len(raw))]
            row += [int(v) for v in x[j][p]]
        rows.append((bpos[b], tuple(row)))
    return rows, {
        "lost": cs.lost,
        "duplicates": cs.duplicates,
        "checkpoints": cs.checkpoints,
        "mismatches": cs.mismatches,
        "checkpoint_repeats": cs.checkpoint_repeats,
        "unreplayed": cs.unreplayed,
        "damaged": cs.damaged,
    }


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
