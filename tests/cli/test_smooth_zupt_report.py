"""``accelnav smooth --zupt auto``: every rest decision explained (issue 23), on the line, in a CSV, in the plots."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest
from support.cli import run_cli as _run

from accelnav.cli import main
from accelnav.data.runfile import load_run
from accelnav.estimate import zupt


@pytest.fixture(scope="module")
def drift_walk(tmp_path_factory):
    path = tmp_path_factory.mktemp("zr") / "walk.npz"
    assert main(["sim", "--scenario", "walking_drift", "--duration", "20", "--seed", "2", "--out", str(path)]) == 0
    return path


def test_report_lists_every_candidate_with_its_reason(drift_walk, tmp_path, capsys):
    report = tmp_path / "rests.csv"
    argv = ["smooth", drift_walk, "--zupt", "auto", "--zupt-report", report, "--out", tmp_path / "s.npz"]
    status, out, _ = _run([*argv, "--plots", tmp_path / "plots"], capsys)
    assert status == 0
    line = next(s for s in out.splitlines() if s.startswith("zero-velocity detector:"))
    m = re.search(r"(\d+) candidate rests, (\d+) accepted(?: \(([^)]*)\))?, (\d+) refused(?: \(([^)]*)\))?", line)
    assert m, line
    n, n_acc, acc, n_ref, ref = int(m[1]), int(m[2]), m[3] or "", int(m[4]), m[5] or ""
    assert n == n_acc + n_ref and n >= 15
    for part, total in ((acc, n_acc), (ref, n_ref)):  # the counts per reason add up
        assert sum(int(x) for x in re.findall(r" (\d+)(?:,|$)", part)) == total
    with open(report, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == n
    for r in rows:
        assert float(r["start_s"]) <= float(r["end_s"]) and int(r["samples"]) > 0
        known = zupt.ACCEPT_REASONS if r["decision"] == "accepted" else zupt.REFUSE_REASONS
        assert r["reason"] in known and r["still_R"] != ""
    assert sum(r["decision"] == "accepted" for r in rows) == n_acc
    arrays, _ = load_run(tmp_path / "s.npz")
    cand = arrays["zupt_candidates"]
    assert cand.shape == (n, 3) and int(cand[:, 2].sum()) == n_acc
    # the accepted rests are the applied updates
    t = arrays["t"]
    for t0, t1, ok in cand:
        inside = (t >= t0) & (t <= t1)
        assert arrays["zupt"][inside, 0].all() == bool(ok)
    assert (tmp_path / "plots" / "smooth.png").stat().st_size > 0
    assert np.isfinite(cand).all()


def test_report_needs_the_detector(drift_walk, tmp_path, capsys):
    status, _, err = _run(
        ["smooth", drift_walk, "--zupt-report", tmp_path / "r.csv", "--out", tmp_path / "s.npz"], capsys
    )
    assert status == 2 and "--zupt-report" in err and err.count("\n") == 1


def test_fixes_decide_and_the_report_names_them(tmp_path, capsys):
    """``--zupt auto --fixes``: the town drive's quiet stretches at speed are refused because the fixes imply
    speed there, and the report's evidence column says so; the still start is named as an assumption."""
    run, fixes = tmp_path / "town.npz", tmp_path / "fixes.csv"
    argv = ["sim", "--scenario", "town_drive", "--duration", "120", "--seed", "1", "--out", run, "--fixes-out", fixes]
    assert _run(argv, capsys)[0] == 0
    report = tmp_path / "rests.csv"
    status, out, _ = _run(
        ["smooth", run, "--zupt", "auto", "--fixes", fixes, "--zupt-report", report, "--out", tmp_path / "s.npz"],
        capsys,
    )
    assert status == 0
    line = next(s for s in out.splitlines() if s.startswith("zero-velocity detector:"))
    assert "still start" in line and "assumed: the run starts at rest" in line
    with open(report, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert all(r["evidence"] for r in rows)
    vetoed = [r for r in rows if r["reason"] == "moving" and "fixes imply" in r["evidence"]]
    assert vetoed, [(r["reason"], r["evidence"]) for r in rows]
    arrays, _ = load_run(tmp_path / "s.npz")
    speed = np.linalg.norm(load_run(run)[0]["u"], axis=1)  # the truth, in the input
    assert speed[arrays["zupt"][:, 0]].max(initial=0.0) < 0.5  # no update where the car moves
