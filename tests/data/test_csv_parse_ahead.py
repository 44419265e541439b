"""The CSV reader's C parser working ahead on other threads (recording.csv_pieces, PARSE_AHEAD) gives the
pieces, numbers, lines and refusals of the reader working piece after piece."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from accelnav.data import recording as rc
from accelnav.errors import UserError


def _pieces(monkeypatch, path: Path, lanes: int, gz: bool = False):
    monkeypatch.setattr(rc, "threads", lambda: lanes)
    monkeypatch.setattr(rc, "CHUNK_CHARS", 700)  # dozens of pieces, a few lines each
    out = []
    try:
        for head, table, nums in rc.csv_pieces(path, None, None, None, None, gz, "m/s^2"):
            out.append((tuple(head.cols), table.tobytes(), table.shape, nums.tobytes()))
    except UserError as exc:
        out.append(("refused", str(exc)))
    return out


def _csv(tmp_path: Path, lines: list[str]) -> Path:
    p = tmp_path / "r.csv"
    p.write_text("\n".join(lines) + "\n")
    return p


def _rows(n: int, seed: int = 2) -> list[str]:
    rng = np.random.default_rng(seed)
    return [f"{k / 100:.2f},{rng.normal():.9g},{rng.normal():.9g}" for k in range(n)]


CASES = {
    "plain": lambda rows: rows,
    "nan and inf": lambda rows: [
        r if k % 97 else r.rsplit(",", 1)[0] + (",nan" if k % 2 else ",inf") for k, r in enumerate(rows)
    ],  # fmt: skip
    "comments and blank lines": lambda rows: [r if k % 131 else "# a note\n\n" + r for k, r in enumerate(rows)],
    "a short line late": lambda rows: rows[:1500] + ["15.00,0.1"] + rows[1500:],
    "text in a number": lambda rows: rows[:1200] + ["12.00,0.1,abc"] + rows[1200:],
}


@pytest.mark.parametrize("case", list(CASES))
def test_parsing_ahead_gives_the_pieces_and_refusals_of_one_thread(tmp_path, monkeypatch, case):
    rows = CASES[case](_rows(2000))
    path = _csv(tmp_path, ["# a recording", "t_s,acc_x_m_s2,acc_y_m_s2", *rows])
    one = _pieces(monkeypatch, path, 1)
    assert len(one) > 20 or one[-1][0] == "refused"
    assert _pieces(monkeypatch, path, 2) == one
    assert _pieces(monkeypatch, path, 3) == one


def test_a_reader_stopped_early_leaves_no_parser_thread(tmp_path, monkeypatch):
    import threading

    path = _csv(tmp_path, ["t_s,acc_x_m_s2,acc_y_m_s2", *_rows(3000)])
    monkeypatch.setattr(rc, "threads", lambda: 2)
    monkeypatch.setattr(rc, "CHUNK_CHARS", 700)
    gen = rc.csv_pieces(path, None, None, None, None, False, "m/s^2")
    for _ in range(5):
        next(gen)
    gen.close()
    assert not [t for t in threading.enumerate() if t.name.startswith("accelnav-csv")]
