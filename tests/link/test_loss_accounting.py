"""Exact loss accounting of sample frames: repeats dropped and counted, gaps of any length counted exactly."""

from __future__ import annotations

import numpy as np
import pytest
from support.naive_decoder import decode_naive

from accelnav.link.codec import encode_command, encode_frames
from accelnav.link.decoder import Decoder, decode_all


def _frames(man, seq, index, flags=None) -> list[bytes]:
    """One encoded sample frame per (seq, index); seq taken modulo 2^16 as the MCU's u16 does."""
    seq = np.asarray(seq, np.int64)
    recs = np.zeros(len(seq), man.dtypes["sample"])
    recs["seq"] = seq % 65536
    recs["index"] = np.asarray(index, np.int64)
    recs["flags"] = 1 if flags is None else flags
    recs["x.code"] = np.arange(len(seq)) % 4096  # contents tell the frames apart
    size = man.frames["sample"]["wire_size"]
    return [bytes(r) for r in np.frombuffer(encode_frames(man, "sample", recs), np.uint8).reshape(-1, size)]


def _check(man, stream: bytes, lost: int, duplicates: int, delivered_index, pieces: int = 7, seed: int = 0):
    """The vectorised decoder, whole and fed in pieces, and the naive decoder agree with the expectation."""
    frames, stats = decode_all(man, stream)
    np.testing.assert_array_equal(frames["sample"]["index"], delivered_index)
    assert (stats.lost, stats.duplicates) == (lost, duplicates)
    d = Decoder(man)
    cuts = np.sort(np.random.default_rng(seed).integers(0, len(stream) + 1, pieces - 1))
    got = [d.feed(stream[a:b])["sample"] for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(stream)], strict=True)]
    np.testing.assert_array_equal(np.concatenate(got), frames["sample"])
    assert (d.stats.lost, d.stats.duplicates) == (lost, duplicates)
    counts = {}
    naive, naive_lost = decode_naive(man, stream, counts)
    assert [r[2] for r in naive["sample"]] == list(delivered_index)
    assert counts == {"lost": lost, "duplicates": duplicates} and naive_lost == lost


def test_a_repeated_chunk_is_dropped_and_counted(man):
    f = _frames(man, range(1000), range(1000))
    # a USB-serial adapter repeats 50 frames, and later a single one
    stream = b"".join(f[:550] + f[500:550] + f[550:800] + f[799:800] + f[800:])
    _check(man, stream, lost=0, duplicates=51, delivered_index=np.arange(1000))


def test_an_older_frame_is_dropped_after_a_gap(man):
    f = _frames(man, range(300), range(300))
    stream = b"".join(f[:100] + f[150:200] + f[120:121] + f[200:])  # 50 lost, then a straggler from the gap
    _check(man, stream, lost=50, duplicates=1, delivered_index=np.r_[0:100, 150:300])


@pytest.mark.parametrize("decimation", [1, 4])
@pytest.mark.parametrize("gap", [100_000, 65_536, 65_535, 131_072 + 7])
def test_a_long_gap_is_counted_exactly(man, gap, decimation):
    k = np.r_[0:1000, 1000 + gap : 2000 + gap]  # frame numbers: `gap` frames never arrive
    stream = b"".join(_frames(man, k, k * decimation))
    _check(man, stream, lost=gap, duplicates=0, delivered_index=k * decimation)


def test_seq_wraps_without_loss(man):
    k = np.arange(140_000)  # two wraps of seq
    _check(man, b"".join(_frames(man, k, k + 5)), lost=0, duplicates=0, delivered_index=k + 5)


def test_a_firmware_reset_starts_the_index_again(man):
    # seq runs on across a reset, the index starts at 0; the first frame after it may be lost (no flag seen)
    seq = np.r_[0:100, 101:200]
    index = np.r_[1000:1100, 1:100]
    flags = np.ones(len(seq), np.int64)
    _check(man, b"".join(_frames(man, seq, index, flags)), lost=1, duplicates=0, delivered_index=index)
    flags[100] |= 1 << man.flags["reset"]  # the reset flag seen, the index later than before the reset
    index2 = np.r_[0:100, 500:599]
    _check(man, b"".join(_frames(man, seq, index2, flags)), lost=1, duplicates=0, delivered_index=index2)


def test_a_long_acknowledged_stop_is_not_a_loss(man):
    # stopped for 200 000 samples: the index runs on, seq does not; the stop's ack is in the stream
    ack = np.zeros(1, man.dtypes["ack"])
    ack["command"] = man.frames["cmd_stop"]["type"]
    ack["index"] = 100
    seq = np.arange(200)
    index = np.r_[0:100, 200_100:200_200]
    f = _frames(man, seq, index)
    stream = b"".join(f[:100]) + encode_frames(man, "ack", ack) + b"".join(f[100:])
    _check(man, stream, lost=0, duplicates=0, delivered_index=index)
    assert encode_command(man, "stop")  # the command the ack answers exists


def test_random_streams_agree_with_the_naive_decoder(man):
    """Repeats, gaps, resets and wraps at random: the vectorised and frame-by-frame decoders agree."""
    rng = np.random.default_rng(11)
    for trial in range(20):
        n = 3000
        step = rng.choice([1, 1, 1, 2, 40_000, 70_000], n, p=[0.9, 0.05, 0.02, 0.02, 0.005, 0.005])
        k = np.cumsum(step)
        index = k * 2
        flags = np.ones(n, np.int64)
        r = int(rng.integers(1, n))
        index[r:] -= index[r]  # a reset
        flags[r] |= (1 << man.flags["reset"]) * int(rng.integers(0, 2))
        f = _frames(man, k, index, flags)
        parts = []
        for i in range(n):
            parts.append(f[i])
            if rng.random() < 0.01:
                a = int(rng.integers(max(0, i - 30), i + 1))
                parts += f[a : i + 1]  # a repeat of recent frames
        stream = b"".join(parts)
        counts = {}
        naive, _ = decode_naive(man, stream, counts)
        assert counts["duplicates"] > 0 or len(parts) == n
        _check(man, stream, counts["lost"], counts["duplicates"], [r[2] for r in naive["sample"]], seed=trial)
        # every frame delivered once, and the loss is what the steps say (the frame at the reset: its seq step)
        assert len(naive["sample"]) == n
        assert [r[1] for r in naive["sample"]] == list(k % 65536)
        assert counts["lost"] == int((step[1:] - 1).sum())
