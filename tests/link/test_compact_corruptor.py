"""An independent corruptor for the compact telemetry, and the properties the decoder keeps under it.

The corruptor knows the wire format only from its definition (COBS, CRC-32 of
zlib, the index in bytes 1..4 of a block or checkpoint payload, a block's
``n`` in byte 6) and uses none of the decoder's code. It damages the firmware's
own telemetry of N samples (host board, cffi) with one kind of fault or all
together, and the decoder reads the result in pieces of random size.

The truth is the firmware's own state of every sample (the same inputs run in
the state mode). Under every fault:

1. every delivered row is the true row of its index: raw input, axis flags and
   the four states of each axis, bit for bit;
2. the delivered indices strictly increase (one run: no reset, no reboot);
3. delivered + lost == E - S, where S is the index of the first original block
   or checkpoint that reached the decoder intact and E the furthest index one
   of them says (a block's end, a checkpoint's index): E - S == N unless the
   fault destroyed the stream's first or last frames (truncation, a bit flip or
   a drop at either end). Duplicates never count as delivered or lost.

Run as a script, it prints the table of faults, frames tried and counts.
"""

from __future__ import annotations

import struct
import sys
import time
import zlib
from functools import cache

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

N = 3000
FAULTS = ("bitflip", "drop", "duplicate", "reorder", "truncate", "poweron", "future", "mixed")


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


def _payload(frame: bytes) -> bytes | None:
    raw = _uncobs(frame[:-1])
    if raw is None or len(raw) < 5 or zlib.crc32(raw[:-4]) != struct.unpack("<I", raw[-4:])[0]:
        return None
    return raw[:-4]


def _frame(payload: bytes) -> bytes:
    return _cobs(payload + struct.pack("<I", zlib.crc32(payload))) + b"\0"


BLOCK, CHECKPOINT = 0x04, 0x05  # codegen.frames' frame types, as the protocol document gives them


def _with_index(frame: bytes, index: int) -> bytes:
    p = bytearray(_payload(frame))
    p[1:5] = struct.pack("<I", index % 2**32)
    return _frame(bytes(p))


def _span(frames: list[bytes], original: set[bytes]) -> tuple[int, int]:
    """(S, E): the index of the first original block or checkpoint among ``frames``, in stream order, and the
    furthest index one of them reaches (a block's end, a checkpoint's index)."""
    first, ends = None, [0]
    for f in frames:
        if f in original:
            p = _payload(f)
            if p[0] in (BLOCK, CHECKPOINT):
                i = struct.unpack("<I", p[1:5])[0]
                first = i if first is None else first
                ends.append(i + p[6] if p[0] == BLOCK else i)
    return first or 0, max(ends)


# --------------------------------------------------------------------------
# faults: (frames, rng) -> (bytes on the wire, frames that survive intact)


def corrupt(kind: str, frames: list[bytes], rng: np.random.Generator) -> bytes:
    f = list(frames)
    n = len(f)
    if kind in ("drop", "mixed"):
        gone = set(rng.choice(n, max(1, n // 20), replace=False).tolist())
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
        compact = [i for i, x in enumerate(f) if (_payload(x) or b"\0")[0] in (BLOCK, CHECKPOINT)]
        for i in rng.choice(compact, min(2, len(compact)), replace=False).tolist():
            f[i] = _with_index(f[i], int(rng.integers(N + 10_000, 2**32)))
    data = bytearray(b"".join(f))
    if kind in ("bitflip", "mixed"):
        for p in rng.integers(0, len(data), 40).tolist():
            data[p] ^= 1 << int(rng.integers(0, 8))
    if kind in ("truncate", "mixed"):
        data = data[: int(rng.integers(len(data) // 3, len(data)))]
    return bytes(data)


# --------------------------------------------------------------------------
# the decoder under test, in pieces


def decode_in_pieces(man, replay, data: bytes, rng: np.random.Generator):
    from accelnav.link.decoder import Decoder

    d = Decoder(man, replay=replay)
    cuts = np.sort(rng.integers(0, len(data) + 1, int(rng.integers(1, 60))))
    rows = [d.feed(data[a:b])["sample"] for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(data)], strict=True)]
    d.finish()
    rows.append(d.release())
    return np.concatenate(rows), d.stats


def check(man, truth: np.ndarray, frames: list[bytes], data: bytes, rows, stats) -> list[str]:
    """The broken properties (empty when all hold)."""
    bad = []
    idx = rows["index"].astype(np.int64)
    if len(idx) and (idx.min() < 0 or idx.max() >= N):
        return [f"index {idx.min()}..{idx.max()} outside the run"]
    if (np.diff(idx) <= 0).any():
        k = int(np.argmin(np.diff(idx)))
        bad.append(f"order: {idx[k]} then {idx[k + 1]}")
    want = truth[idx]
    for ax in man.axes:
        for key in ("code", "flags", "r", "u", "a", "e"):
            if not np.array_equal(rows[f"{ax}.{key}"], want[f"{ax}.{key}"]):
                bad.append(f"content: {ax}.{key} differs from the firmware's")
    segs = [s + b"\0" for s in data.split(b"\0")[:-1]]
    S, E = _span(segs, set(frames))
    if len(rows) + stats.lost != E - S:
        bad.append(f"delivered {len(rows)} + lost {stats.lost} != {E} - {S}")
    return bad


# --------------------------------------------------------------------------
# fixtures


@cache
def _telemetry():
    from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
    from accelnav.link.codec import encode_command, encode_stimulus
    from accelnav.link.decoder import decode_all, replay_for
    from accelnav.model.load import load_model

    man = manifest(None)
    mod = build_firmware(None)
    code = 2048 + np.random.default_rng(21).integers(-400, 400, (N, 2))
    code[[100, 1700], 0] = 0  # rails: refused inputs
    fw = HostFirmware(mod)
    fw.rx(encode_stimulus(man, code=code) + encode_command(man, "flush"))
    stream = fw.take()
    own = HostFirmware(mod)  # the state mode at decimation 1: the firmware's own states of every sample
    own.rx(encode_command(man, "mode_states") + encode_stimulus(man, code=code))
    truth = decode_all(man, own.take())[0]["sample"]
    assert len(truth) == N and (truth["index"] == np.arange(N)).all()
    frames = [s + b"\0" for s in stream.split(b"\0")[:-1]]
    return man, replay_for(man, load_model()), frames, truth


@pytest.fixture(scope="module")
def tele():
    return _telemetry()


@pytest.mark.parametrize("kind", FAULTS)
def test_the_decoder_keeps_its_properties_under_each_fault(tele, kind):
    man, replay, frames, truth = tele
    for trial in range(4):
        rng = np.random.default_rng([FAULTS.index(kind), trial])
        data = corrupt(kind, frames, rng)
        rows, stats = decode_in_pieces(man, replay, data, rng)
        assert not check(man, truth, frames, data, rows, stats), (kind, trial)
        if kind in ("bitflip", "drop", "reorder", "future"):  # the decoder saw real damage or loss
            assert stats.lost + stats.bad_frames + stats.duplicates > 0


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(st.lists(st.sampled_from(FAULTS[:-1]), min_size=1, max_size=4), st.integers(0, 2**32 - 1))
def test_the_decoder_keeps_its_properties_under_faults_hypothesis_combines(kinds, seed):
    man, replay, frames, truth = _telemetry()
    rng = np.random.default_rng(seed)
    data = b"".join(frames)
    for kind in kinds:  # each fault on what the one before left (cut back into frames at the delimiters)
        data = corrupt(kind, [s + b"\0" for s in data.split(b"\0")[:-1]] or frames, rng)
    rows, stats = decode_in_pieces(man, replay, data, rng)
    assert not check(man, truth, frames, data, rows, stats)


def main() -> None:
    """The table: per fault, trials, frames tried, delivered / lost / damaged / duplicates, and whether every
    property held."""
    man, replay, frames, truth = _telemetry()
    trials = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    print(
        f"{'fault':10} {'trials':>6} {'frames':>7} {'delivered':>10} {'lost':>10} {'damaged':>8} {'dups':>7}  outcome"
    )
    t0 = time.perf_counter()
    for kind in FAULTS:
        tot = np.zeros(5, np.int64)
        broken = []
        for trial in range(trials):
            rng = np.random.default_rng([100 + FAULTS.index(kind), trial])
            data = corrupt(kind, frames, rng)
            rows, stats = decode_in_pieces(man, replay, data, rng)
            tot += [data.count(b"\0"), len(rows), stats.lost, stats.bad_frames, stats.duplicates]
            broken += check(man, truth, frames, data, rows, stats)
        outcome = "held" if not broken else f"BROKEN x{len(broken)}: {broken[0]}"
        print(f"{kind:10} {trials:6d} {tot[0]:7d} {tot[1]:10d} {tot[2]:10d} {tot[3]:8d} {tot[4]:7d}  {outcome}")
    print(f"({time.perf_counter() - t0:.1f} s; {N} samples per trial, {len(frames)} frames before damage)")


if __name__ == "__main__":
    main()
