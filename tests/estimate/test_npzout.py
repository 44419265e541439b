"""accelnav.estimate.npzout: an NPZ written in pieces, in any order, that numpy and zipfile read and check."""

from __future__ import annotations

import zipfile
import zlib

import numpy as np
import pytest

from accelnav.errors import UserError
from accelnav.estimate.npzout import NpzWriter, crc32_combine


@pytest.mark.parametrize("split", [0, 1, 7, 1000, 4096])
def test_crc32_combine_equals_the_crc_of_the_whole(split):
    rng = np.random.default_rng(split)
    data = rng.integers(0, 256, 4096 + 13, dtype=np.uint8).tobytes()
    a, b = data[:split], data[split:]
    assert crc32_combine(zlib.crc32(a), zlib.crc32(b), len(b)) == zlib.crc32(data)


def test_pieces_in_any_order_give_a_valid_npz(tmp_path):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(3, 1001, 4))
    c = rng.random((1001, 3)) < 0.5
    path = tmp_path / "o.npz"
    with NpzWriter(path, {"format": np.array("accelnav-run/2"), "x": (x.shape, np.float64), "c": (c.shape, bool)}) as w:
        for j in (2, 0, 1):  # axes out of order, chunks backward
            for s in reversed(range(0, 1001, 97)):
                w.write("x", 4 * (j * 1001 + s), x[j, s : s + 97])
        w.write("c", 0, c)
    assert not (tmp_path / "o.npz.part").exists()
    with zipfile.ZipFile(path) as zf:
        assert zf.testzip() is None  # every member's CRC checks
    with np.load(path) as f:
        assert str(f["format"]) == "accelnav-run/2"
        assert np.array_equal(f["x"], x) and np.array_equal(f["c"], c)


def test_a_member_not_fully_written_is_an_error_and_leaves_no_file(tmp_path):
    path = tmp_path / "o.npz"
    with pytest.raises(ValueError, match="never written"):
        with NpzWriter(path, {"x": ((10,), np.float64)}) as w:
            w.write("x", 0, np.zeros(9))
            w.close()
    w.abort()
    assert not path.exists() and not (tmp_path / "o.npz.part").exists()


def test_large_pieces_written_behind_the_caller_still_tile_and_check(tmp_path):
    """Pieces of 1 MiB and more go through the writer thread (two slots, the caller's buffer reused at
    once): overwriting the caller's buffer after write() must not change what lands in the file."""
    n = 3 * (1 << 17) + 5  # doubles: pieces of 1 MiB and a short tail
    want = np.random.default_rng(1).normal(size=n)
    buf = np.empty(1 << 17)
    with NpzWriter(tmp_path / "big.npz", {"x": ((n,), np.float64)}) as w:
        for s in range(0, n, len(buf)):
            e = min(s + len(buf), n)
            buf[: e - s] = want[s:e]
            w.write("x", s, buf[: e - s])
            buf[:] = np.nan  # the caller reuses its buffer at once
    with zipfile.ZipFile(tmp_path / "big.npz") as z:
        assert z.testzip() is None
    np.testing.assert_array_equal(np.load(tmp_path / "big.npz")["x"], want)


def test_large_pieces_cut_from_wider_rows_are_cast_as_numpy_casts_them(tmp_path):
    """A piece of 1 MiB and more that is a few columns of wider rows (the compact r, u of (m, 4) states), cast to
    a narrower dtype column by column: the bytes of numpy's cast of the whole piece."""
    m = (1 << 18) + 3
    x = np.random.default_rng(2).normal(size=(m, 4)) * np.logspace(-30, 30, m)[:, None]
    with NpzWriter(tmp_path / "c.npz", {"y": ((m, 2), np.float32), "z": ((m, 3), np.float32)}) as w:
        w.write("y", 0, x[:, :2])
        w.write("z", 0, x[:, 1:])
    with np.load(tmp_path / "c.npz") as f:
        assert f["y"].tobytes() == x[:, :2].astype(np.float32).tobytes()
        assert f["z"].tobytes() == x[:, 1:].astype(np.float32).tobytes()


def test_a_write_error_on_the_writer_thread_is_raised_and_leaves_no_file(tmp_path, monkeypatch):
    """A full disk while a piece is written behind the caller: the error reaches the caller (at the next
    write or at close), and neither the output nor its .part remains."""
    import errno
    import os

    real = os.pwrite

    def full(fd, data, pos):
        if len(data) >= 1 << 20:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data, pos)

    monkeypatch.setattr(os, "pwrite", full)
    n = 4 * (1 << 17)
    with pytest.raises(UserError, match="cannot write: No space left on device; nothing was left behind"):
        with NpzWriter(tmp_path / "full.npz", {"x": ((n,), np.float64)}) as w:
            for s in range(0, n, 1 << 17):
                w.write("x", s, np.ones(1 << 17))
    assert not (tmp_path / "full.npz").exists()
    assert not list(tmp_path.iterdir()), list(tmp_path.iterdir())
