"""The CSV reader's whole-piece path (no Python loop over the lines) reads what the line-by-line path reads
and refuses the same lines with the same messages, past the first piece of text."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.data import recording
from accelnav.errors import UserError

N = 40_000  # about 1 MB: several pieces of CHUNK_CHARS


def _table(rng) -> np.ndarray:
    return np.column_stack((np.arange(N) / 100.0, rng.normal(0, 1, (N, 2))))


def _write(path, table, edit=None):
    lines = ["t_s,acc_x_g,acc_y_g"] + [f"{t:.2f},{a:.6f},{b:.6f}" for t, a, b in table]
    if edit:
        edit(lines)
    path.write_text("\n".join(lines) + "\n")
    return path


def test_fast_path_reads_what_the_line_path_reads(tmp_path):
    table = _table(np.random.default_rng(1))
    fast = recording.read_recording(_write(tmp_path / "a.csv", table))

    def comments(lines):  # a comment in every piece sends each through the line-by-line path
        for i in range(len(lines) - 1, 1, -5000):
            lines.insert(i, "# a note")

    slow = recording.read_recording(_write(tmp_path / "b.csv", table, comments))
    assert np.array_equal(fast.accel, slow.accel) and np.array_equal(fast.t, slow.t)
    assert np.array_equal(fast.lines, np.arange(2, N + 2))
    assert fast.accel.shape == (N, 2) and np.allclose(fast.accel / 9.80665, table[:, 1:], atol=1e-6)


@pytest.mark.parametrize(
    "bad,message",
    [
        ("1.00,2.0", "line {line}: 2 fields; the header has 3"),
        ("1.00,2.0,3.0,4.0", "line {line}: 4 fields; the header has 3"),
        ("1.00,x,3.0", "line {line}, column 'acc_x_g' is not a number"),
        ("1.00,,3.0", "line {line}, column 'acc_x_g' is empty"),
    ],
)
def test_a_bad_line_past_the_first_piece_is_named(tmp_path, bad, message):
    k = 30_000  # well past the first piece

    def spoil(lines):
        lines[k] = bad

    path = _write(tmp_path / "bad.csv", _table(np.random.default_rng(2)), spoil)
    with pytest.raises(UserError, match=message.format(line=k + 1)):
        recording.read_recording(path)
