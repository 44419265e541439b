"""The smooth summary shows what the smoother estimated at the start, not r=0+-0 (issue 25)."""

from __future__ import annotations

import re

from accelnav.cli import main


def test_the_start_line_leaves_out_what_is_zero_by_definition(tmp_path, capsys):
    sim, smooth = tmp_path / "sim.npz", tmp_path / "s.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "5", "--seed", "4", "--out", str(sim)]) == 0
    capsys.readouterr()
    assert main(["smooth", str(sim), "--out", str(smooth)]) == 0
    out = capsys.readouterr().out
    starts = [line.split("smoother at start: ")[1] for line in out.splitlines() if "smoother at start: " in line]
    assert len(starts) == 2
    for text in starts:
        assert "+-0;" not in text + ";" and "+-0 " not in text and "r=" not in text and "u=" not in text
        assert "r = u = 0 there by definition" in text
        # the states the smoother did estimate, each with a nonzero sd
        sds = re.findall(r"(a|eps)=[^,]+\+-([0-9.e+-]+)", text)
        assert [s for s, _ in sds] == ["a", "eps"] and all(float(e) > 0 for _, e in sds)
