"""An independent corruptor of the compact telemetry, and the truth to judge the decoder by.

It knows the wire only from its definition (COBS, CRC-32 of zlib, the u32 index in bytes 1..4 of a block
or checkpoint payload and 3..6 of a sample frame, a block's ``n`` in byte 6, the resume flag in byte 5 of
a block or checkpoint) and uses none of the decoder's code. Two sessions of the firmware's own telemetry
(host board, cffi): :func:`plain_session`, N samples in the compact mode, and :func:`pause_session`, which
stops and starts, and changes between the compact and the state mode, so that the stream holds blocks,
checkpoints and sample frames, with resume flags where the firmware paused.

The truth of every sample is the firmware's own state (the same inputs run in the state mode at decimation
1: the filter runs on while stopped). :func:`check` holds a decode against it:

1. every delivered row is the true row of its index (raw input, axis flags, the four states of each axis);
2. the delivered indices strictly increase (one run: no reset, no reboot);
3. ``lost`` is exact: delivered + lost == the samples the firmware sent with an index in [S, E), S the index
   of the first original frame that reached the decoder intact and E the furthest index one of them
   reaches (a block's end, a checkpoint's index, a sample frame's index + 1). Samples the firmware never
   sent (while stopped) are neither. Duplicates never count as delivered or lost.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

BLOCK, CHECKPOINT, SAMPLE, ACK = 0x04, 0x05, 0x01, 0x03  # codegen.frames' frame types (the protocol document)
MODE_COMPACT = 0x19  # the command type of mode_compact, which an ack names in its byte 1
RESUME = 1 << 4  # the resume flag (the protocol document's flag bits)
FAULTS = ("bitflip", "drop", "duplicate", "reorder", "truncate", "poweron", "future", "mixed")
PAUSE_FAULTS = (*FAULTS, "pause")  # "pause": the frames around a resume or a mode change lost together


# --------------------------------------------------------------------------
# the wire, from its definition


def _cobs(data: bytes) -> bytes:
    out, block = bytearray(), bytearray()
    for b in data:
        if b == 0:
            out += bytes([len(block) + 1]) + block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 254:
                out += bytes([255]) + block
                block = bytearray()
    return bytes(out + bytes([len(block) + 1]) + block)


def _uncobs(seg: bytes) -> bytes | None:
    out, i = bytearray(), 0
    while i < len(seg):
        c = seg[i]
        if c == 0 or i + c > len(seg):
            return None
        out += seg[i + 1 : i + c]
        i += c
        if c != 255 and i < len(seg):
            out.append(0)
    return bytes(out)


def payload(frame: bytes) -> bytes | None:
    raw = _uncobs(frame[:-1])
    if raw is None or len(raw) < 5 or zlib.crc32(raw[:-4]) != struct.unpack("<I", raw[-4:])[0]:
        return None
    return raw[:-4]


def frame(p: bytes) -> bytes:
    return _cobs(p + struct.pack("<I", zlib.crc32(p))) + b"\0"


def split(data: bytes) -> list[bytes]:
    return [s + b"\0" for s in data.split(b"\0")[:-1]]


def extent(frame_: bytes) -> tuple[int, int, int] | None:
    """(type, first index, index after it) of a block, checkpoint or sample frame; None for others."""
    p = payload(frame_)
    if p is None or p[0] not in (BLOCK, CHECKPOINT, SAMPLE):
        return None
    if p[0] == SAMPLE:
        i = struct.unpack_from("<I", p, 3)[0]
        return SAMPLE, i, i + 1
    i = struct.unpack_from("<I", p, 1)[0]
    return p[0], i, i + p[6] if p[0] == BLOCK else i


def resumes(frame_: bytes) -> bool:
    p = payload(frame_)
    return p is not None and p[0] in (BLOCK, CHECKPOINT) and bool(p[5] & RESUME)


def _with_index(frame_: bytes, index: int) -> bytes:
    p = bytearray(payload(frame_))
    at = 3 if p[0] == SAMPLE else 1
    p[at : at + 4] = struct.pack("<I", index % 2**32)
    return frame(bytes(p))


def sent(frames: list[bytes]) -> np.ndarray:
    """The indices the firmware sent in ``frames`` (a block's samples, a sample frame's), sorted."""
    out = []
    for f in frames:
        e = extent(f)
        if e is not None and e[0] != CHECKPOINT:
            out.append(np.arange(e[1], e[2]))
    return np.unique(np.concatenate(out)) if out else np.zeros(0, np.int64)


def span(segs: list[bytes], original: set[bytes]) -> tuple[int, int]:
    """(S, E): the index of the first original frame among ``segs`` in stream order and the furthest index
    one of them reaches; the ack of a change to the compact mode reaches its index too (the state mode's
    samples before it had their frames)."""
    first, ends = None, [0]
    for f in segs:
        if f in original:
            e = extent(f)
            if e is not None:
                first = e[1] if first is None else first
                ends.append(e[2])
            elif (p := payload(f)) is not None and p[0] == ACK and p[1] == MODE_COMPACT:
                ends.append(struct.unpack_from("<I", p, 5)[0])
    return first or 0, max(ends)


# --------------------------------------------------------------------------
# faults: (frames, rng) -> bytes on the wire


def corrupt(kind: str, frames: list[bytes], rng: np.random.Generator, n_samples: int) -> bytes:
    f = list(frames)
    n = len(f)
    if kind in ("drop", "mixed"):
        gone = set(rng.choice(n, max(1, n // 20), replace=False).tolist())
        f = [x for i, x in enumerate(f) if i not in gone]
    if kind == "pause":  # at one or two resumes: 1 to 4 frames from a little before it to a little after
        at = [i for i, x in enumerate(f) if resumes(x)]
        gone = set()
        for r in rng.choice(at, min(len(at), int(rng.integers(1, 3))), replace=False).tolist():
            a = r + int(rng.integers(-3, 2))
            gone |= set(range(max(0, a), min(n, a + int(rng.integers(1, 5)))))
        f = [x for i, x in enumerate(f) if i not in gone]
    if kind in ("duplicate", "mixed"):
        for _ in range(6):
            a = int(rng.integers(0, len(f)))
            k = int(rng.integers(1, 12))
            at = min(len(f), a + k + int(rng.integers(0, 30)))
            f[at:at] = f[a : a + k]
    if kind in ("reorder", "mixed"):
        for _ in range(8):
            a = int(rng.integers(0, len(f) - 1))
            f[a], f[a + 1] = f[a + 1], f[a]
    if kind in ("poweron", "mixed"):
        for _ in range(3):
            at = int(rng.integers(len(f) // 4, len(f)))
            f[at:at] = frames[: int(rng.integers(2, 13))]
    if kind in ("future", "mixed"):
        movable = [i for i, x in enumerate(f) if (extent(x) or (SAMPLE,))[0] != SAMPLE]  # blocks, checkpoints
        for i in rng.choice(movable, min(2, len(movable)), replace=False).tolist():
            f[i] = _with_index(f[i], int(rng.integers(n_samples + 10_000, 2**32)))
    data = bytearray(b"".join(f))
    if kind in ("bitflip", "mixed"):
        for p in rng.integers(0, len(data), 40).tolist():
            data[p] ^= 1 << int(rng.integers(0, 8))
    if kind in ("truncate", "mixed"):
        data = data[: int(rng.integers(len(data) // 3, len(data)))]
    return bytes(data)


# --------------------------------------------------------------------------
# the decoder under test, in pieces, and the properties


def decode_in_pieces(man, replay, data: bytes, rng: np.random.Generator):
    from accelnav.link.decoder import Decoder, end_of_stream

    d = Decoder(man, replay=replay)
    cuts = np.sort(rng.integers(0, len(data) + 1, int(rng.integers(1, 60))))
    rows = [d.feed(data[a:b])["sample"] for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(data)], strict=True)]
    rows.append(end_of_stream(d))
    return np.concatenate(rows), d.stats


def expected_total(frames: list[bytes], data: bytes) -> int:
    """The samples the firmware sent with an index in [S, E) of the damaged stream ``data`` (property 3)."""
    S, E = span(split(data), set(frames))
    idx = sent(frames)
    return int(np.count_nonzero((idx >= S) & (idx < E)))


def check(man, truth: np.ndarray, frames: list[bytes], data: bytes, rows, stats) -> list[str]:
    """The broken properties (empty when all hold)."""
    bad = []
    idx = rows["index"].astype(np.int64)
    if len(idx) and (idx.min() < 0 or idx.max() >= len(truth)):
        return [f"index {idx.min()}..{idx.max()} outside the run"]
    if (np.diff(idx) <= 0).any():
        k = int(np.argmin(np.diff(idx)))
        bad.append(f"order: {idx[k]} then {idx[k + 1]}")
    want = truth[idx]
    for ax in man.axes:
        for key in ("code", "flags", "r", "u", "a", "e"):
            if not np.array_equal(rows[f"{ax}.{key}"], want[f"{ax}.{key}"]):
                k = int(np.flatnonzero(rows[f"{ax}.{key}"] != want[f"{ax}.{key}"])[0])
                bad.append(f"content: {ax}.{key} of index {idx[k]} differs from the firmware's")
                break
    total = expected_total(frames, data)
    if len(rows) + stats.lost != total:
        bad.append(f"delivered {len(rows)} + lost {stats.lost} != {total} sent")
    return bad


# --------------------------------------------------------------------------
# the sessions


def pause_trial(t: int, session) -> tuple[str, list[str], int]:
    """Trial t of the corruptor with pauses over ``session`` ((man, replay, frames, truth) of
    :func:`pause_session`): (fault, broken properties, delivered + lost - sent)."""
    man, replay, frames, truth = session
    kind = PAUSE_FAULTS[t % len(PAUSE_FAULTS)]
    rng = np.random.default_rng([30, t])
    data = corrupt(kind, frames, rng, len(truth))
    rows, stats = decode_in_pieces(man, replay, data, rng)
    return kind, check(man, truth, frames, data, rows, stats), len(rows) + stats.lost - expected_total(frames, data)


def _truth(man, mod, code: np.ndarray) -> np.ndarray:
    """The firmware's own states of every sample: the same inputs in the state mode at decimation 1."""
    from accelnav.hil_sim.targets.firmware import HostFirmware
    from accelnav.link.codec import encode_command, encode_stimulus
    from accelnav.link.decoder import decode_all

    own = HostFirmware(mod)
    own.rx(encode_command(man, "mode_states") + encode_stimulus(man, code=code))
    truth = decode_all(man, own.take())[0]["sample"]
    assert len(truth) == len(code) and (truth["index"] == np.arange(len(code))).all()
    return truth


def _codes(n: int, seed: int) -> np.ndarray:
    code = 2048 + np.random.default_rng(seed).integers(-400, 400, (n, 2))
    code[[100, n // 2 + 17], 0] = 0  # rails: refused inputs
    return code


def plain_session(n: int = 3000):
    """(man, mod, frames, truth): n samples in the compact mode, then a flush."""
    from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
    from accelnav.link.codec import encode_command, encode_stimulus

    man, mod = manifest(None), build_firmware(None)
    code = _codes(n, 21)
    fw = HostFirmware(mod)
    fw.rx(encode_stimulus(man, code=code) + encode_command(man, "flush"))
    return man, mod, split(fw.take()), _truth(man, mod, code)


# (command, samples after it): stops with and without samples while stopped, both mode changes, a stop in
# the state mode, a mode change while stopped; the pauses fall inside blocks and on checkpoint boundaries
PAUSES = (
    (None, 700), ("stop", 150), ("start", 530), ("mode_states", 240), ("mode_compact", 600), ("stop", 0),
    ("start", 300), ("mode_states", 90), ("stop", 60), ("start", 120), ("mode_compact", 256), ("stop", 40),
    ("mode_states", 0), ("mode_compact", 0), ("start", 450),
)  # fmt: skip


def pause_session():
    """(man, mod, frames, truth): the firmware's telemetry over :data:`PAUSES`, then a flush."""
    from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
    from accelnav.link.codec import encode_command, encode_stimulus

    man, mod = manifest(None), build_firmware(None)
    code = _codes(sum(k for _, k in PAUSES), 22)
    fw = HostFirmware(mod)
    at = 0
    for cmd, k in PAUSES:
        if cmd is not None:
            fw.rx(encode_command(man, cmd))
        if k:
            fw.rx(encode_stimulus(man, code=code[at : at + k]))
        at += k
    fw.rx(encode_command(man, "flush"))
    return man, mod, split(fw.take()), _truth(man, mod, code)
