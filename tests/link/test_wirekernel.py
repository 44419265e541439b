"""The C kernel that COBS-decodes and CRC-checks frames (accelnav.link.wirekernel) against the decoder's
numpy path and zlib: frame by frame on valid, damaged and random frames, and whole decodes of a damaged
stream with and without it."""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from accelnav.link.codec import cobs_decode_rows, crc_rows, encode_frames
from accelnav.link.decoder import Decoder
from accelnav.link.wirekernel import decode_frames, wire_lib


@pytest.fixture(scope="module")
def mod():
    lib = wire_lib()
    if lib is None:
        pytest.skip("no C compiler: the decoder uses its numpy path")
    return lib


def _numpy(buf: np.ndarray, starts: np.ndarray, L: int):
    rows = np.lib.stride_tricks.sliding_window_view(buf, L)[starts]
    dec, ok = cobs_decode_rows(rows)
    m = L - 1
    return dec, ok, crc_rows(dec[:, : m - 4]) == dec[:, m - 4 :].copy().view("<u4").ravel()


@pytest.mark.parametrize("name", ["sample", "block", "checkpoint", "ack"])
def test_kernel_equals_the_numpy_path_and_zlib(mod, man, name):
    """Frames of every length the decoder meets: intact ones (each CRC also checked against zlib), ones
    with a non-zero byte changed, and rows of random non-zero bytes (chains that run past the end, 0xFF
    codes, chains that land exactly on it): decoded bytes and both verdicts equal, row for row."""
    rng = np.random.default_rng(len(name))
    dt = man.dtypes[name]
    n = 400
    recs = rng.integers(0, 256, (n, dt.itemsize), dtype=np.uint8).view(dt).ravel()
    wire = np.frombuffer(encode_frames(man, name, recs), np.uint8).reshape(n, -1)[:, :-1].copy()
    L = wire.shape[1]
    hit = wire[n // 3 : 2 * n // 3]
    cols = rng.integers(0, L, len(hit))
    old = hit[np.arange(len(hit)), cols].astype(np.int64)  # COBS bytes: never zero
    hit[np.arange(len(hit)), cols] = (old - 1 + rng.integers(1, 255, len(hit))) % 255 + 1  # another non-zero byte
    noise = rng.integers(1, 256, (n, L), dtype=np.uint8)
    for row in noise[: n // 4]:  # chains of short hops that land exactly on the end: well formed
        pos = 0
        while pos < L:
            row[pos] = min(int(rng.integers(1, 9)), L - pos)
            pos += int(row[pos])
    rows = np.concatenate([wire, noise])
    buf = np.concatenate([np.r_[7, 7, 7].astype(np.uint8), rows.ravel()])  # frames off the buffer's start
    starts = 3 + np.arange(len(rows), dtype=np.int64) * L
    dec, ok, crc = decode_frames(mod, buf, starts, L)
    want = _numpy(buf, starts, L)
    np.testing.assert_array_equal(dec, want[0])
    np.testing.assert_array_equal(ok, want[1])
    np.testing.assert_array_equal(crc, want[2])
    assert ok[: n // 3].all() and crc[: n // 3].all()  # the intact frames
    assert not (ok & crc)[n // 3 : 2 * n // 3].any()  # one byte changed: never both
    assert 0 < np.count_nonzero(ok[n:]) < n  # random rows: some chains well formed, some not
    for k in range(0, n, 37):
        assert crc[k] == (zlib.crc32(dec[k, :-4].tobytes()) == int.from_bytes(dec[k, -4:].tobytes(), "little"))


def test_kernel_refuses_a_frame_past_the_buffer(mod):
    with pytest.raises(ValueError, match="past the buffer"):
        decode_frames(mod, bytes(20), np.array([10]), 11)


def test_decoder_with_and_without_the_kernel_agree(mod, man):
    """A stream of sample frames with damage of every kind, decoded in pieces through the kernel and through
    the numpy path: the same frames and the same counts."""
    rng = np.random.default_rng(9)
    n = 3000
    recs = rng.integers(0, 256, (n, man.dtypes["sample"].itemsize), dtype=np.uint8).view(man.dtypes["sample"])
    recs = recs.ravel().copy()
    recs["seq"] = np.arange(n)
    recs["index"] = np.arange(n)
    buf = bytearray(encode_frames(man, "sample", recs))
    for p in rng.integers(0, len(buf), 60):
        buf[p] = int(rng.integers(0, 256))
    del buf[5000:5100]
    buf[9000:9000] = bytes(rng.integers(0, 256, 300, dtype=np.uint8))
    data = bytes(buf)
    out = []
    for kernel in (True, False):
        d = Decoder(man, kernel=kernel)
        assert (d._wire is not None) == kernel
        cuts = np.r_[0, np.sort(rng.integers(0, len(data), 7)), len(data)]
        got = [d.feed(data[a:b])["sample"] for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
        out.append((np.concatenate(got), d.stats.as_dict()))
    np.testing.assert_array_equal(out[0][0], out[1][0])
    assert out[0][1] == out[1][1]
    assert out[0][1]["crc_errors"] > 0 and out[0][1]["bad_frames"] > 0 and len(out[0][0]) > n // 2
