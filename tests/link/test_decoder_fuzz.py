"""Structure-aware fuzz of the host's link decoder (compact mode included) and of the log reader.

The inputs start from what the real firmware sends (the SIL build, a session that goes through
compact blocks and checkpoints, a zupt, a stop and start, a decimated stretch of sample frames,
state mode and a reset) and are damaged frame by frame, mostly with the CRC recomputed so that
the damage reaches the decoder's rules instead of stopping at the CRC: frames dropped, repeated,
moved, fields rewritten, indices shifted, plus plain bit flips, garbage and cut frames, and the
stream fed in pieces of random size. The log fuzz wraps such streams in a recorder log and then
damages the log's own structure (chunk and header, again mostly with valid CRCs).

Property: no exception but the documented refusals (LogError for a file that is not a readable
log, ModelError for a model text the loader refuses), and output bounded by the input (no more
sample rows than block frames can carry).

The seed is random per run and printed; ACCELNAV_FUZZ_SEED=N reruns one exactly.
"""

from __future__ import annotations

import os
import random
import struct
import tempfile
import zlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st

from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import cobs_decode, encode_command, encode_stimulus, frame
from accelnav.link.decoder import Decoder, replay_for
from accelnav.link.logfile import CHUNK, MAGIC, LogError, LogWriter
from accelnav.link.recorder import decode_log
from accelnav.model.load import DEFAULT_MODEL, ModelError

SEED = int(os.environ.get("ACCELNAV_FUZZ_SEED") or random.SystemRandom().randrange(2**32))
# no shrinking: a failure is reported at once with its seed and example (shrinking one took minutes)
FUZZ = settings(
    max_examples=int(os.environ.get("ACCELNAV_FUZZ_EXAMPLES", "1000")),
    derandomize=False,
    database=None,
    deadline=None,
    phases=(Phase.explicit, Phase.generate),
    suppress_health_check=list(HealthCheck),
)


@pytest.fixture(scope="module", autouse=True)
def _say_seed():
    print(f"\nhost decoder fuzz: seed {SEED} (rerun: ACCELNAV_FUZZ_SEED={SEED})")


MAN = manifest(None)
MODEL_TEXT = DEFAULT_MODEL.read_text()
B = MAN.frames["block"]["fields"][-1]["dtype"]  # e.g. "(32,)<u2": the block's slots
SLOTS = int(B[1 : B.index(",")])


def _session() -> bytes:
    """What the firmware sends over one session that visits every frame kind and mode."""
    fw = HostFirmware(build_firmware(None))
    rng = np.random.default_rng(7)

    def stim(n: int) -> bytes:
        code = 2048 + rng.integers(-300, 300, (n, len(MAN.axes)))
        code[rng.random(n) < 0.01, 0] = 0  # rails now and then: refused inputs
        return encode_stimulus(MAN, code=code)

    def cmd(name: str, **kw) -> bytes:
        return encode_command(MAN, name, **kw)

    parts = [
        stim(300),
        cmd("info"),
        cmd("zupt_begin"),
        stim(70),
        cmd("zupt_end"),
        cmd("stop"),
        stim(20),
        cmd("start"),
        stim(100),
        cmd("decimate", factor=3),
        stim(30),
        cmd("decimate", factor=1),
        cmd("mode_states"),
        stim(10),
        cmd("mode_compact"),
        cmd("reset"),
        stim(280),
        cmd("flush"),
    ]
    for p in parts:
        fw.rx(p)
    return fw.take()


STREAM = _session()
FRAMES = [f + b"\0" for f in STREAM.split(b"\0")[:-1]]


@pytest.fixture(scope="module")
def replay():
    return replay_for(MAN, MODEL_TEXT)


def _refame(f: bytes, edit) -> bytes:
    """Frame f with its payload edited by edit(bytearray) and its CRC made right again."""
    raw = cobs_decode(f[:-1])
    if raw is None or len(raw) < 5:
        return f
    p = bytearray(raw[:-4])
    edit(p)
    return frame(bytes(p))


def _set(off: int, data: bytes):
    def edit(p: bytearray) -> None:
        at = off % len(p)
        p[at : at + len(data)] = data[: len(p) - at]

    return edit


def _shift_index(delta: int):
    """Move the u32 index: bytes 1..4 of block, checkpoint and ack payloads, 3..6 of a sample frame."""

    def edit(p: bytearray) -> None:
        at = 3 if p[0] == MAN.frames["sample"]["type"] else 1
        if len(p) >= at + 4:
            v = (int.from_bytes(p[at : at + 4], "little") + delta) % 2**32
            p[at : at + 4] = v.to_bytes(4, "little")

    return edit


DELTAS = st.sampled_from([1, -1, SLOTS, -SLOTS, 256, -256, 2**31, 2**32 - 1, 10**6]) | st.integers(-(2**32), 2**32)
OP = st.one_of(
    st.tuples(st.just("drop"), st.integers(0, 10**6)),
    st.tuples(st.just("repeat"), st.integers(0, 10**6), st.integers(0, 10**6)),
    st.tuples(st.just("move"), st.integers(0, 10**6), st.integers(0, 10**6)),
    st.tuples(st.just("field"), st.integers(0, 10**6), st.integers(0, 255), st.binary(min_size=1, max_size=8)),
    st.tuples(st.just("index"), st.integers(0, 10**6), DELTAS),
    st.tuples(st.just("flip"), st.integers(0, 10**6), st.integers(0, 8 * 200)),
    st.tuples(st.just("garbage"), st.integers(0, 10**6), st.binary(min_size=1, max_size=64)),
    st.tuples(st.just("cut"), st.integers(0, 10**6), st.integers(0, 200)),
)


def _damage(ops) -> bytes:
    fs = list(FRAMES)
    for op in ops:
        kind, i = op[0], op[1] % len(fs)
        if not fs[i] and kind in ("flip", "cut"):
            continue
        if kind == "drop" and len(fs) > 1:
            del fs[i]
        elif kind == "repeat":
            fs.insert(op[2] % (len(fs) + 1), fs[i])
        elif kind == "move":
            f = fs.pop(i)
            fs.insert(op[2] % (len(fs) + 1), f)
        elif kind == "field":
            fs[i] = _refame(fs[i], _set(op[2], op[3]))
        elif kind == "index":
            fs[i] = _refame(fs[i], _shift_index(op[2]))
        elif kind == "flip":
            f = bytearray(fs[i])
            f[(op[2] // 8) % len(f)] ^= 1 << (op[2] % 8)
            fs[i] = bytes(f)
        elif kind == "garbage":
            fs.insert(i, op[2])
        elif kind == "cut":
            fs[i] = fs[i][: op[2] % len(fs[i])]
    return b"".join(fs)


def _pieces(data: bytes, cuts: list[int]) -> list[bytes]:
    at = sorted({c % (len(data) + 1) for c in cuts})
    return [data[a:b] for a, b in zip([0, *at], [*at, len(data)], strict=True)]


def _bound(stream: bytes) -> int:
    """Most sample rows a stream can make: a block's slots per delimited segment."""
    return SLOTS * (stream.count(b"\0") + 1)


REACHED = dict.fromkeys(
    ("examples", "rows", "lost", "duplicates", "mismatches", "checkpoints", "checkpoint_repeats", "crc_errors"), 0
)


@seed(SEED)
@FUZZ
@given(ops=st.lists(OP, min_size=1, max_size=12), cuts=st.lists(st.integers(0, 10**6), max_size=12))
def test_decoder_takes_damaged_streams(replay, ops, cuts):
    stream = _damage(ops)
    d = Decoder(MAN, replay=replay)
    rows = 0
    for piece in _pieces(stream, cuts):
        batch = d.feed(piece)
        rows += len(batch["sample"])
        assert all(len(batch[n]) <= stream.count(b"\0") for n in d.names if n != "sample")
    d.finish()
    rows += len(d.release())
    assert rows <= _bound(stream)
    s = d.stats.as_dict()
    assert all(v >= 0 for k, v in s.items() if k != "frames"), s
    assert s["bytes"] == len(stream)
    REACHED["examples"] += 1
    REACHED["rows"] += rows
    for k in ("lost", "duplicates", "mismatches", "checkpoints", "checkpoint_repeats", "crc_errors"):
        REACHED[k] += s[k] > 0  # examples in which that rule of the decoder acted


def test_the_fuzz_reached_the_decoders_rules():
    """Runs after the property test (file order): the damage got past the CRC to every rule."""
    if REACHED["examples"] == 0:
        pytest.skip("the property test did not run in this session")
    print(f"\nhost decoder fuzz, examples in which each rule acted: {dict(REACHED)}")
    assert all(REACHED[k] > 0 for k in REACHED), REACHED


# ---- the log reader -----------------------------------------------------------------------------

TMP = Path(tempfile.mkdtemp(prefix="acn-logfuzz-"))
META = {"manifest": MAN.data, "model_toml": MODEL_TEXT, "source": "fuzz", "started_utc": "2026-01-01T00:00:00Z"}


def _log_bytes(chunks: list[bytes], meta: dict | bytes = META) -> bytes:
    """A log as LogWriter writes it (checked against LogWriter below), header JSON given as bytes or dict."""
    import json

    head = meta if isinstance(meta, bytes) else json.dumps({"format": "accelnav-log/1", **meta}).encode()
    out = bytearray(MAGIC + struct.pack("<I", len(head)) + head + struct.pack("<I", zlib.crc32(head)))
    for k, body in enumerate(chunks):
        lt = struct.pack("<IQ", len(body), 10**18 + k * 10**8)
        out += CHUNK + lt + struct.pack("<I", zlib.crc32(body, zlib.crc32(lt))) + body
    return bytes(out)


def test_the_log_builder_writes_what_log_writer_writes():
    path = TMP / "writer.acnlog"
    t = iter(range(10**18, 10**18 + 10**10, 10**8))
    with LogWriter(path, META, clock=lambda: next(t), overwrite=True) as log:
        for piece in (b"ab", b"cd\0"):
            log.append(piece)
            log.flush()
    import json

    head = json.dumps({"format": "accelnav-log/1", **META}, sort_keys=True).encode()
    assert path.read_bytes()[: 12 + len(head)] == _log_bytes([], head)[: 12 + len(head)]
    ok = decode_log(path)
    assert ok.chunks == 2 and ok.stats["bytes"] == 5


JSONISH = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=6), kids, max_size=4),
    max_leaves=12,
)


def _edit_meta(kind: str, key: str, value) -> dict | bytes:
    """Header damage with a valid CRC: a key of the meta or of the manifest changed or removed, or not JSON."""
    import copy

    meta = copy.deepcopy(META)
    man = meta["manifest"]
    if kind == "meta":
        keys = sorted(meta)
        meta[keys[hash(key) % len(keys)]] = value
    elif kind == "meta_drop":
        keys = sorted(meta)
        del meta[keys[hash(key) % len(keys)]]
    elif kind == "manifest":
        keys = sorted(man)
        man[keys[hash(key) % len(keys)]] = value
    elif kind == "frame":  # one frame's description
        name = sorted(man["frames"])[hash(key) % len(man["frames"])]
        fr = man["frames"][name]
        keys = sorted(fr)
        fr[keys[hash(key[::-1]) % len(keys)]] = value
    elif kind == "not_json":
        return key.encode("utf-8", "surrogatepass") + b"\xff{"
    return meta


HEADER = st.tuples(
    st.sampled_from(["none", "meta", "meta_drop", "manifest", "frame", "not_json"]), st.text(max_size=6), JSONISH
)
FILE_OP = st.one_of(
    st.tuples(st.just("flip"), st.integers(0, 10**7)),
    st.tuples(st.just("truncate"), st.integers(0, 10**7)),
    st.tuples(st.just("insert"), st.integers(0, 10**7), st.binary(min_size=1, max_size=32)),
    st.tuples(st.just("chunk_magic"), st.integers(0, 10**7)),  # a stray "ACNK" inside the data
)


@seed(SEED)
@FUZZ
@given(
    ops=st.lists(OP, max_size=8),
    cuts=st.lists(st.integers(0, 10**6), max_size=6),
    header=HEADER,
    file_ops=st.lists(FILE_OP, max_size=3),
)
def test_log_reader_takes_damaged_logs(ops, cuts, header, file_ops):
    stream = _damage(ops)
    meta = META if header[0] == "none" else _edit_meta(*header)
    buf = bytearray(_log_bytes(_pieces(stream, cuts), meta))
    for op in file_ops:
        at = op[1] % (len(buf) + 1)
        if op[0] == "flip" and at < len(buf):
            buf[at] ^= 1 << (op[1] % 8)
        elif op[0] == "truncate":
            del buf[at:]
        elif op[0] == "insert":
            buf[at:at] = op[2]
        elif op[0] == "chunk_magic":
            buf[at:at] = CHUNK
    path = TMP / "fuzz.acnlog"
    path.write_bytes(bytes(buf))
    try:
        d = decode_log(path)
    except (LogError, ModelError) as exc:  # the log's model text goes through the model loader's rule first
        assert "\n" not in str(exc) and str(exc)
        return
    assert len(d.frames["sample"]) <= SLOTS * (len(buf) // 2 + 1)
    assert d.damaged_bytes + d.torn_bytes <= len(buf)
