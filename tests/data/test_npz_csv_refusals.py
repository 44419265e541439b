"""Recordings the reader fuzz (tests/data/test_reader_fuzz.py) found ending in tracebacks: each is now
refused in one line (UserError) or read as the user meant."""

from __future__ import annotations

import io
import struct
import zipfile

import numpy as np
import pytest

from accelnav.data.recording import read_recording
from accelnav.errors import UserError

N = 200


def _npz(tmp_path, **arrays):
    base = {"t": np.arange(N) / 100.0, "accel": np.zeros((N, 2)), "axis_names": np.array(["x", "y"])}
    base.update(arrays)
    path = tmp_path / "r.npz"
    np.savez(path, **{k: v for k, v in base.items() if v is not None})
    return path


@pytest.mark.parametrize(
    "arrays",
    [
        {"accel": np.array([["a", "b"]] * N)},
        {"t": np.array(["soon"] * N)},
        {"accel": np.zeros((N, 2), complex)},
        {"t": None, "rate_hz": np.array([100.0, 200.0])},
        {"t": None, "rate_hz": np.array(["fast"])},
        {"clipped": np.array(True)},
        {"clipped": np.zeros((N, 3), bool)},
    ],
    ids=[
        "accel strings",
        "t strings",
        "accel complex",
        "rate_hz two numbers",
        "rate_hz string",
        "clipped scalar",
        "clipped 3 columns for 2 axes",
    ],
)
def test_npz_arrays_of_the_wrong_kind_are_refused_in_one_line(tmp_path, arrays):
    with pytest.raises(UserError) as e:
        read_recording(_npz(tmp_path, **arrays))
    assert "\n" not in str(e.value)


def test_a_damaged_npy_header_is_refused_in_one_line(tmp_path):
    head = b"{'descr': '<f8', 'fortran_order': False, 'shape': (3,"  # cut: numpy's tokenizer fails
    head += b" " * (-(len(head) + 11) % 64) + b"\n"
    member = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head + np.zeros(3).tobytes()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("accel.npy", member)
    path = tmp_path / "d.npz"
    path.write_bytes(buf.getvalue())
    with pytest.raises(UserError, match="not a .npy array"):
        read_recording(path)


def test_a_time_column_named_by_an_empty_name_is_the_time(tmp_path):
    rows = "\n".join(f"{k / 100},{0.001 * (k % 3)}" for k in range(N))
    path = tmp_path / "r.csv"
    path.write_text(f",acc_x_g\n{rows}\n")
    rec = read_recording(path, time_column="")
    assert rec.n == N and rec.t[1] == pytest.approx(0.01)
