"""accelnav tune as a command: its report and the model file it writes (the library's result: equal to
accelnav.tune's on the same run), its refusals, and the recordings and ZUPT files it reads. What the
estimates are worth is tested on the library, tests/estimate/test_tune.py."""

from __future__ import annotations

import numpy as np
from support.cli import run_cli

import accelnav
from accelnav.cli import main
from accelnav.model.edit import dump_model, revalidate, with_noise
from accelnav.model.load import DEFAULT_MODEL, load_model


def test_writes_the_librarys_tuned_model_with_its_report(tmp_path, capsys):
    run = tmp_path / "sg.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "30", "--seed", "3", "--out", str(run)]) == 0
    start_model = revalidate(with_noise(load_model(DEFAULT_MODEL), sigma_n=5.0, R=0.05))
    start = tmp_path / "start.toml"
    start.write_text(dump_model(start_model))
    out = tmp_path / "tuned.toml"
    capsys.readouterr()
    argv = ["tune", run, "--model", start, "--zupt", "auto", "--max-evaluations", "40", "--out", out]
    status, text, err = run_cli(argv, capsys)
    assert status == 0, err
    assert "| sigma_n |" in text and "significantly better" in text and "written" in text
    assert out.read_text().startswith("# accelnav model written by accelnav tune\n")
    arrays, _ = accelnav.load_run(run)
    expected, _ = accelnav.tune(
        arrays, start_model, rest=accelnav.detect_rests(arrays, start_model), max_evaluations=40
    )
    assert load_model(out).noise == expected.noise


def test_refusals(tmp_path, capsys):
    run = tmp_path / "s.npz"
    assert main(["sim", "--scenario", "stationary", "--duration", "5", "--out", str(run)]) == 0
    capsys.readouterr()
    assert main(["tune", str(run), "--figures", "sigma_x", "--out", str(tmp_path / "o.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--figures: sigma_x unknown" in err and "\n" not in err


def test_takes_a_csv_recording_and_a_zupt_file(tmp_path, capsys):
    """tune reads recordings through the same checked reader as filter and smooth, and ZUPT files in smooth's form."""
    run = tmp_path / "sg.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "30", "--seed", "3", "--out", str(run)]) == 0
    d = np.load(run)
    csv = tmp_path / "rec.csv"
    rows = np.column_stack([d["t"], d["accel"]])
    np.savetxt(csv, rows, delimiter=",", header="t,ax_m_s2,ay_m_s2", comments="", fmt="%.9g")
    rest = np.all(d["u"] == 0, axis=1).astype(int)
    zfile = tmp_path / "rest.csv"
    np.savetxt(zfile, rest, header="rest", comments="", fmt="%d")
    out = tmp_path / "tuned.toml"
    capsys.readouterr()
    args = ["tune", str(csv), "--time-column", "t", "--axis", "ax_m_s2", "--axis", "ay_m_s2", "--unit", "m/s^2"]
    assert main([*args, "--zupt", str(zfile), "--figures", "R", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    n_rest = int(rest.sum())
    assert f"zero-velocity updates per axis {n_rest}, {n_rest}" in text
    assert 0.005 < load_model(out).noise.R < 0.025
    # a rate that is not the model's is refused in one line, as for smooth
    assert main([*args[:2], "--rate", "50", "--axis", "ax_m_s2", "--out", str(out)]) == 2
    assert "\n" not in capsys.readouterr().err.strip()


def test_report_names_a_figure_at_the_sensors_bound(default_model):
    """A simulated walk drives R to the sensor's noise floor (issue 31's foot case): the report says so."""
    from accelnav.cli.tune import report
    from accelnav.estimate.tune import tune_run

    run = accelnav.simulate(default_model, "walking", 20.0, seed=1)
    _, r = tune_run(default_model, run, rest=accelnav.detect_rests(run, default_model), max_evaluations=150)
    lines = report(r)
    (row,) = [x for x in lines if x.startswith("| R |")]
    assert row.endswith("| NO: at its lower bound (the sensor's rounding and datasheet noise floor, 0.00158) |")
    assert "(the search stopped at its evaluation limit)" in [x for x in lines if x.startswith("ln L")][0]
