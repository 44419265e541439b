"""accelnav sim / filter / smooth / demo: files, summaries, CSV export and refusals."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from conftest import MODELS
from support.cli import run_cli as _run

from accelnav.data.runfile import FORMAT, FORMAT_V1, FORMAT_V3, load_run


def test_sim_filter_smooth_chain(tmp_path, capsys):
    sim, filt, smooth = tmp_path / "sim.npz", tmp_path / "filt.npz", tmp_path / "smooth.npz"
    status, out, _ = _run(["sim", "--scenario", "stop_and_go", "--duration", 5, "--seed", 4, "--out", sim], capsys)
    assert status == 0 and "500 samples" in out
    arrays, model = load_run(sim)
    # nothing a /1 reader lacks: written as /1, which older readers take
    assert str(arrays["format"]) == FORMAT_V1 and model.name == "adxl250_default"
    assert arrays["code"].dtype == np.int32 and arrays["accel"].shape == (500, 2)

    # by default the filter writes the need (r, u and their sds at float32, no echo); --full what smooth reads again
    status, out, _ = _run(["filter", sim, "--out", filt], capsys)
    assert status == 0 and "filter at end" in out
    arrays, _ = load_run(filt)
    assert str(arrays["format"]) == FORMAT_V3 and "accel" not in arrays
    assert arrays["filt_x"].shape == (2, 500, 2) and arrays["filt_x"].dtype == np.float32
    assert arrays["filt_sd"].shape == (2, 500, 2) and arrays["filt_sd"].dtype == np.float32
    compact_r = arrays["filt_x"][:, :, 0].copy()
    status, _, err = _run(["smooth", filt, "--out", smooth], capsys)  # it holds no input to smooth: said so
    assert status != 0 and "output without its input" in err and "--full" in err and len(err.strip().splitlines()) == 1

    status, out, _ = _run(["filter", sim, "--full", "--out", filt, "--csv", tmp_path / "f.csv"], capsys)
    assert status == 0 and "filter at end" in out and "double integration" in out
    arrays, _ = load_run(filt)
    np.testing.assert_allclose(compact_r, arrays["filt_x"][:, :, 0], rtol=1e-7, atol=1e-7)
    assert arrays["filt_x"].shape == (2, 500, 4) and arrays["filt_sd"].shape == (2, 500, 4)
    assert "smooth_x" not in arrays and "filt_P" not in arrays  # the covariances only on request
    assert str(arrays["format"]) == FORMAT

    status, out, _ = _run(["smooth", filt, "--full", "--out", smooth, "--plots", tmp_path / "plots"], capsys)
    assert status == 0 and "smoother at start" in out
    arrays, _ = load_run(smooth)
    # the smoother's last sample is the filter's
    assert np.array_equal(arrays["smooth_x"][:, -1], arrays["filt_x"][:, -1])
    assert (tmp_path / "plots" / "smooth.png").stat().st_size > 10_000

    with open(tmp_path / "f.csv") as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    assert len(rows) == 501 and "x_code" in header and "y_filt_eps_sd" in header and "x_true_r" in header
    col = header.index("x_filt_r")
    assert float(rows[-1][col]) == pytest.approx(load_run(filt)[0]["filt_x"][0, -1, 0], rel=1e-9)


def test_smooth_runs_the_filter_when_needed_and_duty_model(tmp_path, capsys):
    sim, smooth = tmp_path / "sim.npz", tmp_path / "smooth.npz"
    model = MODELS / "adxl202_duty.toml"
    status, _, _ = _run(["sim", "--model", model, "--scenario", "sinusoid", "--duration", 3, "--out", sim], capsys)
    assert status == 0
    status, _, _ = _run(["smooth", sim, "--full", "--out", smooth], capsys)
    arrays, m = load_run(smooth)
    assert status == 0 and m.sensor.kind == "duty_cycle"
    assert "t1" in arrays and "filt_x" in arrays and "smooth_x" in arrays


@pytest.mark.parametrize(
    "argv,words",
    [
        (["sim", "--scenario", "moon", "--out", "{tmp}/x.npz"], "--scenario: unknown scenario 'moon'"),
        (["sim", "--duration", "-1", "--out", "{tmp}/x.npz"], "duration_s"),
        (["sim", "--duration", "99999", "--out", "{tmp}/x.npz"], "max_run_s"),
        (["sim"], "--out"),
        (["filter", "{tmp}/missing.npz", "--out", "{tmp}/y.npz"], "missing.npz: no such file"),
        (["filter", "{tmp}/garbage.npz", "--out", "{tmp}/y.npz"], "not an accelnav run file"),
        (["smooth", "{tmp}/other.npz", "--out", "{tmp}/y.npz"], "format is 'missing'"),
    ],
)
def test_bad_input_is_one_line(tmp_path, capsys, argv, words):
    (tmp_path / "garbage.npz").write_bytes(b"not a zip file at all")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    status, _, err = _run([a.format(tmp=tmp_path) for a in argv], capsys)
    assert status == 2
    assert err.startswith("accelnav: error: ") and err.count("\n") == 1 and "Traceback" not in err
    assert words in err, err


def test_model_override_must_match_axes(tmp_path, capsys):
    sim = tmp_path / "sim.npz"
    assert _run(["sim", "--duration", 1, "--out", sim], capsys)[0] == 0
    status, _, err = _run(["filter", sim, "--model", MODELS / "adxl202_duty.toml", "--out", tmp_path / "f.npz"], capsys)
    # same axis names (x, y): accepted, and the override's numbers are used
    assert status == 0, err
    one_axis = tmp_path / "one.toml"
    text = (MODELS / "adxl250_default.toml").read_text()
    one_axis.write_text(text[: text.index('[[axes]]\nname = "y"')] + text[text.index("[noise]") :])
    status, _, err = _run(["filter", sim, "--model", one_axis, "--out", tmp_path / "f.npz"], capsys)
    assert status == 2 and "do not match" in err
