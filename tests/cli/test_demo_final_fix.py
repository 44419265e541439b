"""The demo's smoother rows show what smoothing does: one good position fix at the end (issue 25)."""

from __future__ import annotations

from accelnav.cli import main
from accelnav.cli.demo import FIX_SIGMA_M


def test_a_final_fix_makes_the_smoother_differ_from_the_firmware_filter(tmp_path, capsys):
    assert main(["demo", "--warmup", "900", "--duration", "15", "--pil", "off", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    rows = {}  # (axis, estimate) -> (rms, final); columns: axis, estimate, rms, final, max |e|
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 5 and parts[0] in ("x", "y"):
            rows[(parts[0], " ".join(parts[1:-3]))] = (float(parts[-3]), abs(float(parts[-2])))
    for axis in ("x", "y"):
        fw_rms, fw_final = rows[(axis, "firmware filter")]
        rms, final = rows[(axis, "smoother + final fix")]
        assert final <= 4 * FIX_SIGMA_M, rows  # the fix holds the end
        assert rms < fw_rms and abs(rms - fw_rms) > 0.01, rows  # and the whole track comes back with it
    report = (tmp_path / "report.md").read_text()
    assert "smoother + final fix" in report and "Figure 12" in report
