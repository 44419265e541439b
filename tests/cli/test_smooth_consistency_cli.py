"""accelnav smooth's lines about the model's consistency (issue 23 a) and its --tune flags, on the stiff vehicle
of tests/support/vehicle_fixes.py. The numbers behind them are tested on the library in
tests/estimate/test_model_consistency.py; here, what the command says, and that the model it saves after
--tune is the library's tune_run result."""

from __future__ import annotations

import pytest
from support.cli import run_cli
from support.vehicle_fixes import vehicle_case, write_files

from accelnav.data.runfile import load_run
from accelnav.estimate.pipeline import BASELINES
from accelnav.estimate.tune import tune_run
from accelnav.model.edit import dump_model


@pytest.fixture(scope="module")
def vehicle():
    return vehicle_case()


def test_the_stiff_model_loses_to_the_baselines_and_smooth_says_so(vehicle, tmp_path, capsys):
    run, shipped, _, fixes = vehicle
    path, fx_csv = write_files(tmp_path, run, shipped, fixes)
    status, text, err = run_cli(["smooth", path, "--fixes", fx_csv, "--out", tmp_path / "o.npz"], capsys)
    assert status == 0, err
    assert "fixes disagree with the model: mean NIS" in text and "too stiff" in text
    assert "the smoother misses the held-out fixes more than" in text
    assert "against the truth the smoother" in text
    for name in BASELINES:
        assert name in text


def test_right_model_is_quiet_and_tune_saves_the_librarys_model(vehicle, tmp_path, capsys):
    run, shipped, right, fixes = vehicle
    path, fx_csv = write_files(tmp_path, run, shipped, fixes)
    model_path = tmp_path / "right.toml"
    model_path.write_text(dump_model(right))
    argv = ["smooth", path, "--model", model_path, "--fixes", fx_csv, "--out", tmp_path / "r.npz"]
    status, text, err = run_cli(argv, capsys)
    assert status == 0, err
    assert "consistent with the model" in text and "try --tune" not in text

    argv = ["smooth", path, "--fixes", fx_csv, "--tune", "--out", tmp_path / "t.npz"]
    status, text, err = run_cli(argv, capsys)
    assert status == 0, err
    assert "budget 300 evaluations, 60 s" in text and "; used" in text
    assert "try --tune" not in text and "not identified" not in text and "converged" in text
    _, model = load_run(tmp_path / "t.npz")  # the saved run carries the tuned model
    expected, _ = tune_run(shipped, run, fixes=fixes, max_evaluations=300)
    assert model.noise == expected.noise


def test_tune_stops_at_its_time_budget(vehicle, tmp_path, capsys):
    run, shipped, _, fixes = vehicle
    path, fx_csv = write_files(tmp_path, run, shipped, fixes)
    argv = ["smooth", path, "--fixes", fx_csv, "--tune", "--tune-seconds", "1e-6", "--out", tmp_path / "b.npz"]
    status, text, err = run_cli(argv, capsys)
    assert status == 0, err
    assert "stopped at its budget" in text
    status, _, err = run_cli([*argv[:-2], "--tune-evaluations", "3", "--out", tmp_path / "c.npz"], capsys)
    assert status == 2
    assert "--tune-evaluations: got 3" in err
