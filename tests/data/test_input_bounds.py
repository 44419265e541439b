"""The recording readers are bounded (issue 21, item 10 and 12): sizes checked before anything is inflated,
CSV read in pieces, non-regular files refused before a read, no message echoes more than a short excerpt."""

from __future__ import annotations

import io
import os
import struct
import tracemalloc
import zipfile

import numpy as np
import pytest

from accelnav.cli import main
from accelnav.data.recording import read_recording
from accelnav.errors import UserError
from accelnav.fileio import atomic_output, input_limit, load_npz


def _one_line(argv, capsys) -> str:
    """Run the CLI, expect a one-line refusal (status 2) and return it."""
    status = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert status == 2 and err.startswith("accelnav: error: ") and err.count("\n") == 1, err[:500]
    assert len(err) < 500, f"{len(err)} characters: {err[:200]}..."
    return err


def _recording_npz(path, n=2000):
    t = np.arange(n) / 100.0
    np.savez(path, t=t, accel=np.zeros((n, 2)), axis_names=np.array(["x", "y"]))
    return path


def _patch_sizes(path, member: str, size: int) -> None:
    """Make the zip's local and central headers of ``member`` declare ``size`` uncompressed bytes."""
    data = bytearray(path.read_bytes())
    name = member.encode()
    for sig, off in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):  # uncompressed size field of each header
        at = 0
        while (at := data.find(sig, at)) >= 0:
            name_at = at + (30 if sig == b"PK\x03\x04" else 46)
            if data[name_at : name_at + len(name)] == name:
                struct.pack_into("<I", data, at + off, size)
            at += 4
    path.write_bytes(bytes(data))


def test_an_npz_whose_zip_header_declares_gigabytes_is_refused_before_inflating(tmp_path):
    path = _recording_npz(tmp_path / "bomb.npz")
    _patch_sizes(path, "accel.npy", 0xF000_0000)  # 3.75 GiB declared for a few KB of data
    with zipfile.ZipFile(path) as z:
        assert z.getinfo("accel.npy").file_size == 0xF000_0000  # the crafted file says what it should
    with pytest.raises(UserError, match=r"declare 3\.75 GiB uncompressed \('accel'.*accepted: at most"):
        read_recording(path)


def test_an_npy_header_declaring_a_terabyte_is_refused_not_allocated(tmp_path, capsys):
    path = tmp_path / "huge.npz"
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (1 << 36, 2)})
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("accel.npy", header.getvalue() + bytes(64))
        z.writestr("t.npy", header.getvalue() + bytes(64))
    err = _one_line(["smooth", path, "--out", tmp_path / "o.npz"], capsys)
    assert "declares shape (68719476736, 2) (1.02e+03 GiB)" in err and "damaged" in err


def test_the_limit_is_documented_and_adjustable(tmp_path, monkeypatch):
    path = _recording_npz(tmp_path / "r.npz")
    assert load_npz(path)["accel"].shape == (2000, 2)
    monkeypatch.setenv("ACCELNAV_MAX_INPUT_BYTES", "1000")
    assert input_limit() == 1000
    with pytest.raises(UserError, match="ACCELNAV_MAX_INPUT_BYTES"):
        load_npz(path)


def test_random_bytes_named_npz_are_not_an_npz_file(tmp_path, capsys):
    path = tmp_path / "x.npz"
    path.write_bytes(bytes(np.random.default_rng(3).integers(0, 256, 5000, dtype=np.uint8)))
    err = _one_line(["smooth", path, "--out", tmp_path / "o.npz"], capsys)
    assert "not an NPZ file" in err and "pickle" not in err


def test_an_object_array_is_refused_without_unpickling(tmp_path):
    path = tmp_path / "obj.npz"
    np.savez(path, accel=np.array([{"a": 1}, None], dtype=object))
    with pytest.raises(UserError, match="holds Python objects"):
        load_npz(path)


def _csv(n: int, newline: str = "\n", extra: int = 0) -> str:
    rng = np.random.default_rng(5)
    head = ["t", "acc_x_g", "acc_y_g"] + [f"note{i}" for i in range(extra)]
    rows = [newline.join([",".join(head)])]
    pad = ",".join(["1234567.125"] * extra)
    for k, (a, b) in enumerate(rng.normal(0, 0.01, (n, 2))):
        rows.append(f"{k / 100:.2f},{a:.6f},{b:.6f}" + ("," + pad if extra else ""))
    return newline.join(rows) + newline


@pytest.mark.parametrize("newline", ["\r", "\r\n"])
def test_cr_line_endings_read_like_lf(tmp_path, newline):
    (tmp_path / "lf.csv").write_bytes(_csv(500).encode())
    (tmp_path / "cr.csv").write_bytes(_csv(500, newline).encode())
    lf = read_recording(tmp_path / "lf.csv")
    cr = read_recording(tmp_path / "cr.csv")
    np.testing.assert_array_equal(cr.accel, lf.accel)
    np.testing.assert_array_equal(cr.t, lf.t)
    assert cr.where(10) == lf.where(10) == "sample 10 (line 12)"


def test_a_file_of_nuls_gives_a_short_message(tmp_path, capsys):
    path = tmp_path / "zeros.csv"
    path.write_bytes(bytes(1 << 20))
    err = _one_line(["fit-bias", path, "--out", tmp_path / "m.toml"], capsys)
    assert "NUL byte" in err


def test_a_header_without_newline_is_cut_in_the_message(tmp_path, capsys):
    path = tmp_path / "wide.csv"
    path.write_text(",".join(f"column_{i}" for i in range(20000)) + "\n1,2\n")  # 250 KB of header
    err = _one_line(["fit-bias", path, "--out", tmp_path / "m.toml"], capsys)
    assert "no time column" in err


def test_csv_memory_is_bounded_by_the_numbers_not_the_text(tmp_path):
    path = tmp_path / "wide.csv"
    path.write_text(_csv(40_000, extra=20))  # about 250 bytes of text per row, 32 bytes of kept numbers
    size = path.stat().st_size
    tracemalloc.start()
    try:
        rec = read_recording(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert rec.n == 40_000
    # the text is never held whole (the old reader held it three times over: bytes, str and its lines)
    assert peak < 0.5 * size, f"peak {peak / 1e6:.1f} MB for a {size / 1e6:.1f} MB file"


@pytest.mark.parametrize("kind", ["directory", "symlink loop", "FIFO", "/dev/zero"])
def test_what_is_not_a_regular_file_is_named(tmp_path, capsys, kind):
    path = tmp_path / "in.csv"
    if kind == "directory":
        path.mkdir()
    elif kind == "symlink loop":
        os.symlink(tmp_path / "other", path)
        os.symlink(path, tmp_path / "other")
    elif kind == "FIFO":
        os.mkfifo(path)  # a read would block: refused before it
    else:
        path = "/dev/zero"  # a read would never end
    err = _one_line(["smooth", path, "--out", tmp_path / "o.npz"], capsys)
    said = {"directory": "a directory", "symlink loop": "a symlink loop", "FIFO": "a FIFO", "/dev/zero": "device"}
    assert said[kind] in err and "no such file" not in err


def test_an_unreadable_file_is_one_line(tmp_path, capsys, monkeypatch):
    path = tmp_path / "r.csv"
    path.write_text(_csv(200))
    real_open = io.open

    def deny(file, *a, **k):  # mode 000 as seen by a user who is not root (the suite runs as root)
        if str(file) == str(path):
            raise PermissionError(13, "Permission denied", str(file))
        return real_open(file, *a, **k)

    monkeypatch.setattr("builtins.open", deny)
    monkeypatch.setattr("io.open", deny)
    err = _one_line(["smooth", path, "--out", tmp_path / "o.npz"], capsys)
    assert "Permission denied" in err


def test_atomic_output_leaves_nothing_on_failure(tmp_path):
    out = tmp_path / "x.csv"
    with pytest.raises(KeyboardInterrupt):
        with atomic_output(out) as fh:
            fh.write(b"partial")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    with atomic_output(out) as fh:
        fh.write(b"whole")
    assert out.read_bytes() == b"whole" and list(tmp_path.iterdir()) == [out]
    assert out.stat().st_mode & 0o777 == 0o666 & ~_umask()


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m
