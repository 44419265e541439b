"""``accelnav fit-bias`` as a command: its report, the model file it writes (the library's: equal to
accelnav.characterise's on the same recording), its plots, the recording reader's refusals, the real
recording. The figures themselves are tested on the library: tests/identify/test_characterise_merge.py."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import MODELS
from support.fit_bias_cases import ADIS, band_limited_phone, fine_model, same_model, sim_npz, warm_up, write_csv

import accelnav
from accelnav.cli import main
from accelnav.model.load import load_model

# --------------------------------------------------------------------------
# Recordings for the command


def _files(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.png"))


def test_csv_end_to_end(tmp_path, capsys):
    # x: a warm-up (c1 = 8 mg, T = 40 s); y: a constant bias; both in g, gzip CSV with a time column.
    t = np.arange(24_000) / 100.0
    sigma = 0.01  # g
    x = warm_up(t, 0.008, 0.005, 40.0, sigma, 1)
    y = warm_up(t, 0.0, -0.012, 40.0, sigma, 2)
    rec = write_csv(tmp_path / "rest.csv.gz", {"t_s": t, "acc_x_g": x, "acc_y_g": y})
    out = tmp_path / "fitted.toml"
    plots = tmp_path / "plots"
    assert main(["fit-bias", str(rec), "--out", str(out), "--plots", str(plots)]) == 0
    text = capsys.readouterr().out
    assert "axis x (column acc_x_g, in g)" in text and "T identified" in text
    assert "constant bias" in text and "Ljung-Box" in text and "cumulative periodogram" in text
    # white noise: the composite check finds the white R adequate over the band and keeps it
    assert "the white-noise R represents this band" in text and "understates the noise" not in text
    # the numbers: tests/identify/test_characterise_merge.py; the file holds the library's model
    assert same_model(load_model(out), accelnav.characterise(rec).model)
    # the written file carries the provenance as comments
    assert out.read_text().startswith("# accelnav model written by accelnav fit-bias\n")
    pngs = _files(plots)
    assert [p.name for p in pngs] == sorted(
        f"{a}_{k}.png" for a in "xy" for k in ("fit", "spectrum", "allan", "acf", "noise_model")
    )
    assert all(p.stat().st_size > 5000 for p in pngs)


def test_sim_npz_merges_into_its_embedded_model(tmp_path, capsys, default_model):
    ax = default_model.axes
    model = fine_model(default_model, [dataclasses.replace(ax[0], c1=0.3, c2=0.05, T=40.0), ax[1]])
    npz = sim_npz(tmp_path / "run.npz", model, 200.0, 3)
    out = tmp_path / "m.toml"
    assert main(["fit-bias", str(npz), "--axis", "x", "--out", str(out), "--sigma-n", "paper"]) == 0
    text = capsys.readouterr().out
    assert "from the paper's rule" in text
    assert same_model(load_model(out), accelnav.characterise(npz, axes=["x"], sigma_n="paper").model)


def test_given_model_is_the_base(tmp_path, capsys):
    t = np.arange(12_000) / 100.0
    rec = write_csv(
        tmp_path / "r.csv", {"time_ms": t * 1000, "accel_z_m_s2": warm_up(t, 0.0, 0.3, 1.0, 0.01, 4)}, gz=False
    )
    out = tmp_path / "m.toml"
    base = MODELS / "adxl202_duty.toml"
    assert main(["fit-bias", str(rec), "--model", str(base), "--out", str(out)]) == 0
    assert same_model(load_model(out), accelnav.characterise(rec, base).model)


# --------------------------------------------------------------------------
# Refusals: one line on stderr, exit status 2, saying what and where


def _good(n=12_000):
    t = np.arange(n) / 100.0
    return t, warm_up(t, 0.0, 0.01, 1.0, 0.005, 5)


def _case_nan(tmp):
    t, x = _good()
    x[1234] = np.nan
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "first at sample 1234 (t = 12.34 s)"


def _case_empty_cell(tmp):
    t, x = _good()
    p = write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x}, gz=False)
    lines = p.read_text().splitlines()
    lines[101] = lines[101].split(",")[0] + ","
    p.write_text("\n".join(lines) + "\n")
    return [p], "line 102, column 'acc_x_g' is empty"


def _case_gap(tmp):
    t, x = _good()
    t[5000:] += 0.5
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "gap in time of 0.51 s at t = 49.99 s"


def _case_backwards(tmp):
    t, x = _good()
    t[[700, 701]] = t[[701, 700]]
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "time does not increase at sample 701"


def _case_constant(tmp):
    t, _ = _good()
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": np.full(len(t), 0.02)})], "the signal is constant"


def _case_rail(tmp):
    t, x = _good()
    x = np.minimum(x, 0.012)  # a rail just above the mean: many samples pile up there
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "sit at the maximum"


def _case_flagged(tmp, default_model):
    npz = sim_npz(tmp / "run.npz", default_model, 80.0, 1)
    d = dict(np.load(npz))
    d["clipped"][4321, 0] = True
    np.savez(npz, **d)
    return [npz], "1 samples are flagged clipped, the first at sample 4321"


def _case_full_scale(tmp):
    t, _ = _good()
    x = np.where(np.arange(len(t)) % 7 == 0, 2.0, 1.9)  # the ADXL202's 2 g rail
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x}), "--model", str(MODELS / "adxl202_duty.toml")], (
        "at the sensor's full scale"
    )


def _case_short(tmp):
    t, x = _good(3000)
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "too short: 29.99 s"


def _case_no_column(tmp):
    t, x = _good()
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x}), "--axis", "q"], "no column 'q'"


def _case_unknown_unit(tmp):
    t, x = _good()
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x}), "--unit", "furlong"], "unit 'furlong' is not known"


def _case_no_unit(tmp):
    t, x = _good()
    return [write_csv(tmp / "r.csv", {"t_s": t, "accx": x})], "does not say its unit"


def _case_no_time(tmp):
    _, x = _good()
    return [write_csv(tmp / "r.csv", {"acc_x_g": x})], "no time column"


def _case_missing_file(tmp):
    return [str(tmp / "nothing.csv")], "no such file"


def _case_not_csv(tmp):
    p = tmp / "r.bin"
    p.write_bytes(bytes(range(256)) * 4)
    return [p], "not UTF-8"


CASES = {
    "nan": _case_nan,
    "empty cell": _case_empty_cell,
    "gap": _case_gap,
    "time backwards": _case_backwards,
    "constant": _case_constant,
    "rail pile-up": _case_rail,
    "flagged clipped": _case_flagged,
    "full scale": _case_full_scale,
    "too short": _case_short,
    "no column": _case_no_column,
    "unknown unit": _case_unknown_unit,
    "no unit": _case_no_unit,
    "no time": _case_no_time,
    "missing file": _case_missing_file,
    "not csv": _case_not_csv,
}


@pytest.mark.parametrize("case", list(CASES))
def test_refusals_are_one_line(case, tmp_path, capsys, default_model):
    make = CASES[case]
    args, expected = make(tmp_path, default_model) if case == "flagged clipped" else make(tmp_path)
    out = tmp_path / "never.toml"
    status = main(["fit-bias", *[str(a) for a in args], "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith("accelnav: error: ") and err.count("\n") == 1, err
    assert expected in err, err
    assert "Traceback" not in err and not out.exists()


# --------------------------------------------------------------------------
# The real stationary recording (ADIS16405, 1e6 samples at 100 Hz, in g)


def test_real_recording_report_and_files(tmp_path, capsys):
    """The command on the real recording (its figures: tests/identify/test_characterise_merge.py)."""
    if not ADIS.is_file():
        pytest.skip(f"the real recording is not here: {ADIS} (../shared/data is absent on this machine)")
    out = tmp_path / "adis.toml"
    assert main(["fit-bias", str(ADIS), "--out", str(out), "--axis", "z", "--plots", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "axis z (column acc_z_g, in g)" in text
    assert "WARNING: poor fit" in text and "fits this band poorly" in text
    data = tomllib.loads(out.read_text())
    assert [a["name"] for a in data["axes"]] == ["x", "y", "z"]
    assert len(_files(tmp_path)) == 5


def test_band_limited_recording_is_flagged_and_R_raised(tmp_path, capsys):
    rec, _ = band_limited_phone(tmp_path)
    out = tmp_path / "phone.toml"
    assert main(["fit-bias", str(rec), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "WARNING: the white-noise R understates the noise in this band" in text
    assert same_model(load_model(out), accelnav.characterise(rec).model)  # R raised: see test_characterise_merge
    assert "R raised to the band's R" in out.read_text()
