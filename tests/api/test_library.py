"""The library as a notebook user calls it: the same checks as the command, runs in and out as DataFrames."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import MODELS

import accelnav
from accelnav.cli import main
from accelnav.estimate import pipeline
from accelnav.hil_sim.sim.sensor import simulate as sim_run

FOOT = MODELS / "foot_imu.toml"
G0 = 9.80665


@pytest.fixture(scope="module")
def walk():
    """30 s of the walking scenario on the 200 Hz foot IMU: truth and samples in m/s^2."""
    return sim_run(accelnav.load_model(FOOT), "walking", 30.0, 5)


def _arrays(walk) -> dict:
    return {"t": walk.t, "axis_names": np.array(walk.axis_names), "accel": walk.accel, "clipped": walk.clipped}


def _phone_csv(path, walk) -> None:
    """A phone-style CSV: a millisecond clock and the two axes in g."""
    rows = ["t_ms,acc_x_g,acc_y_g"]
    rows += [f"{1e3 * t:.3f},{a / G0:.9f},{b / G0:.9f}" for t, (a, b) in zip(walk.t, walk.accel, strict=True)]
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.parametrize("call", ["smooth_run", "filter_run", "detect_rests", "tune"])
def test_a_model_made_for_another_rate_is_refused_through_the_library(walk, call):
    """200 Hz data and the 100 Hz default model: the command refuses it; so does every library entry."""
    default = accelnav.load_model(None)
    assert default.rate_hz == 100.0 and [a.name for a in default.axes] == list(walk.axis_names)
    with pytest.raises(accelnav.UserError) as err:
        getattr(accelnav, call)(_arrays(walk), default)
    msg = str(err.value)
    assert "\n" not in msg and "sampled at 200 Hz" in msg and "sampling.rate_hz = 100 Hz" in msg


def test_the_estimators_themselves_refuse_it(walk):
    """Below the face too: pipeline.smooth_run returned x = hundreds of metres on such data."""
    with pytest.raises(accelnav.UserError, match="sampled at 200 Hz"):
        pipeline.smooth_run(_arrays(walk), accelnav.load_model(None))


def test_the_library_and_the_command_refuse_with_the_same_rate_check(walk, tmp_path, capsys):
    path = tmp_path / "walk.csv"
    _phone_csv(path, walk)
    default = MODELS / "adxl250_default.toml"
    with pytest.raises(accelnav.UserError) as err:
        accelnav.read_input(path, default)
    assert main(["smooth", str(path), "--model", str(default), "--out", str(tmp_path / "o.npz")]) == 2
    assert str(err.value) in capsys.readouterr().err


def test_arrays_without_a_key_are_one_line_not_a_KeyError(walk):
    arrays = _arrays(walk)
    del arrays["axis_names"]
    with pytest.raises(accelnav.UserError, match=r"no 'axis_names' in the arrays \(keys: accel, clipped, t\)"):
        accelnav.smooth_run(arrays, accelnav.load_model(FOOT))


def test_a_path_a_mapping_and_a_dataframe_read_alike(walk, tmp_path):
    pd = pytest.importorskip("pandas")
    path = tmp_path / "walk.csv"
    _phone_csv(path, walk)
    model = accelnav.load_model(FOOT)
    from_file, m1 = accelnav.read_input(path, model)
    frame = pd.read_csv(path)
    from_frame, m2 = accelnav.read_input(frame, model)
    from_index, _ = accelnav.read_input(frame.set_index("t_ms"), model)  # the clock as the index
    from_dict, _ = accelnav.read_input({c: frame[c].to_numpy() for c in frame.columns}, model)
    assert m1 is model and m2 is model
    for other in (from_frame, from_index, from_dict):
        assert other.axis_names == ["x", "y"]
        for key in ("t", "accel", "clipped"):
            np.testing.assert_array_equal(other[key], from_file[key])
    # named _g, the columns are read in g, although the calibrated model's samples are in m/s^2
    np.testing.assert_allclose(from_file.accel, walk.accel, atol=1e-8 * G0)


def test_in_memory_columns_get_the_recordings_checks(walk):
    model = accelnav.load_model(FOOT)
    cols = {"t": walk.t.copy(), "acc_x_g": walk.accel[:, 0] / G0, "acc_y_g": walk.accel[:, 1] / G0}
    cols["acc_x_g"][100] = np.nan
    with pytest.raises(accelnav.UserError, match="sample 100 is not a number"):
        accelnav.read_input(cols, model)
    cols["acc_x_g"][100] = 0.0
    cols["t"] = np.delete(cols["t"], np.s_[200:240])
    for k in ("acc_x_g", "acc_y_g"):
        cols[k] = np.delete(cols[k], np.s_[200:240])
    with pytest.raises(accelnav.UserError, match="gap"):
        accelnav.read_input(cols, model)
    run, _ = accelnav.read_input(cols, model, allow_gaps=True)  # filled in, flagged, predicted across
    assert len(run.t) == len(walk.t) and run["clipped"][200:240].all()
    with pytest.raises(accelnav.UserError, match="does not say its unit"):
        accelnav.read_input({"t": walk.t, "acc_x": walk.accel[:, 0], "acc_y": walk.accel[:, 1]}, None)


def test_smooth_with_rests_and_fixes_out_as_a_dataframe(walk, tmp_path):
    pd = pytest.importorskip("pandas")
    model = accelnav.load_model(FOOT)
    run, model = accelnav.read_input(_arrays(walk), model)
    fixes = tmp_path / "fixes.csv"
    ks = [0, len(walk.t) // 2, len(walk.t) - 1]
    fixes.write_text(
        "time_s,position_m,sigma_m,axis\n"
        + "".join(f"{walk.t[k]:.6f},{walk.r[k, j]:.6f},0.05,{ax}\n" for k in ks for j, ax in enumerate("xy"))
    )
    rest = accelnav.detect_rests(run, model)
    assert rest.dtype == bool and 0 < rest.mean() < 1
    out = accelnav.smooth_run(run, model, rest=rest, fixes=fixes)
    assert isinstance(out, accelnav.Run)
    df = out.to_dataframe()
    assert isinstance(df, pd.DataFrame) and len(df) == len(walk.t)
    np.testing.assert_array_equal(df["x_smooth_r"].to_numpy(), out.position()[:, 0])
    np.testing.assert_array_equal(df.index.to_numpy(), walk.t)
    # the fixes hold the smoothed track to the truth where they are, within 4 of the smoother's sigma
    sd = df[["x_smooth_r_sd", "y_smooth_r_sd"]].to_numpy()
    err = np.abs(out.position() - walk.r)
    assert np.all(err[ks] <= 4 * sd[ks])
    assert out["zupt"].any() and len(out["fixes"]) == 6


def test_a_run_goes_out_and_back_as_npz_and_csv(walk, tmp_path):
    model = accelnav.load_model(FOOT)
    run = accelnav.filter_run(accelnav.read_input(_arrays(walk), model)[0], model)
    run.to_npz(tmp_path / "r.npz", model)
    back, m = accelnav.load_run(tmp_path / "r.npz")
    assert isinstance(back, accelnav.Run) and m.text == model.text
    np.testing.assert_array_equal(back["filt_x"], run["filt_x"])
    run.to_csv(tmp_path / "r.csv")
    header = (tmp_path / "r.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "t_s" and "x_filt_r" in header and "y_filt_eps_sd" in header


def test_position_errors_come_as_a_table():
    pd = pytest.importorskip("pandas")
    model = accelnav.load_model(FOOT)
    truth = accelnav.simulate(model, "walking", 30.0, 5)
    rows = accelnav.position_errors(accelnav.smooth_run(truth, model), model)
    df = rows.to_dataframe()
    assert set(df["axis"]) == {"x", "y"} and "smoother" in set(df["method"])
    assert isinstance(df, pd.DataFrame)


def test_generate_returns_the_firmwares_files_as_text():
    files = accelnav.generate(accelnav.load_model(None))
    assert {"accelnav.h", "accelnav.c", "acnframe.h", "acnframe.c"} <= set(files)
    assert all(isinstance(v, str) and v for v in files.values())


def test_run_sil_takes_only_a_simulated_run(walk):
    model = accelnav.load_model(FOOT)  # calibrated: no raw input for firmware
    with pytest.raises(accelnav.UserError, match="run_sil/run_pil: not a run of simulate"):
        accelnav.run_sil(model, _arrays(walk))


def test_the_face_is_listed_and_loads_lazily(tmp_path):
    names = {"Model", "ModelError", "load_model", "save_model", "read_input", "load_run", "save_run", "filter_run",
             "smooth_run", "detect_rests", "position_errors", "characterise", "calibrate", "tune", "generate",
             "simulate", "run_sil", "run_pil"}  # fmt: skip
    assert names <= set(accelnav.__all__) and set(accelnav.__all__) <= set(dir(accelnav))
    code = (
        "import sys, pydoc, accelnav\n"
        "heavy = sorted(m for m in sys.modules if m.startswith(('accelnav.', 'numpy', 'scipy')))\n"
        "text = pydoc.render_doc(accelnav, renderer=pydoc.plaintext)\n"
        "print(heavy, all(n in text for n in accelnav.__all__))"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().endswith("True")
    assert done.stdout.split("]")[0] == "[", f"import accelnav loaded {done.stdout}"


def test_save_model_refuses_before_it_writes(tmp_path):
    import dataclasses

    model = accelnav.load_model(None)
    bad = dataclasses.replace(model, axes=model.axes * 2)  # four axes: the loader refuses that
    out = tmp_path / "m.toml"
    with pytest.raises(accelnav.ModelError):
        accelnav.save_model(out, bad)
    assert not out.exists()
    back = accelnav.save_model(out, model)
    assert back.text == out.read_text() and back.axes == model.axes


def test_characterise_gives_the_model_fit_bias_writes(tmp_path, capsys):
    """The library's chain is the command's: the same recording gives the same merged model."""
    t = np.arange(12_000) / 100.0
    rng = np.random.default_rng(3)
    x = 0.008 * -np.expm1(-t / 30.0) + 0.005 + 0.01 * rng.standard_normal(len(t))
    y = -0.012 + 0.01 * rng.standard_normal(len(t))
    rec = tmp_path / "rest.csv"
    rec.write_text(
        "t_s,acc_x_g,acc_y_g\n" + "".join(f"{a:.2f},{b:.9g},{c:.9g}\n" for a, b, c in zip(t, x, y, strict=True))
    )
    ch = accelnav.characterise(rec)
    assert main(["fit-bias", str(rec), "--out", str(tmp_path / "fit.toml")]) == 0
    capsys.readouterr()
    written = accelnav.load_model(tmp_path / "fit.toml")
    assert [(a.name, a.c1, a.c2, a.T) for a in written.axes] == [(a.name, a.c1, a.c2, a.T) for a in ch.model.axes]
    assert written.noise == ch.model.noise and written.rate_hz == ch.model.rate_hz
    pd = pytest.importorskip("pandas")
    df = ch.to_dataframe()
    assert isinstance(df, pd.DataFrame) and list(df.index) == ["x", "y"] and bool(df.loc["x", "T_identified"])


def test_run_sil_gives_the_firmwares_states_as_hil_compares_them():
    from accelnav.hil_sim.sim.sensor import SimRun
    from accelnav.hil_sim.targets import hil
    from accelnav.hil_sim.targets.firmware import manifest

    model = accelnav.load_model(None)
    run = accelnav.simulate(model, "stop_and_go", 10.0, 1)
    out = accelnav.run_sil(model, run)
    sim = SimRun.from_arrays(model, dict(run))
    c = hil.compare(model, sim, hil.run_sil(model, hil.stimulus(manifest(model.source), sim)))
    assert c.max_of_bound <= 1.0  # within the generator's stated bound of the float64 filter
    for i, key in enumerate(("r", "u", "a", "eps")):
        np.testing.assert_array_equal(out["fw_x"][:, :, i].T, c.fw[key])
    np.testing.assert_array_equal(out["r"], run["r"])  # the truth rides along


def test_rests_found_elsewhere_are_decided_as_candidates(walk):
    """detect_rests(candidates=): the decision runs on the given candidates (accelnav.level's gyro-aided rests)
    instead of the accelerometer-only detector's, accepts only among them, and refuses a mask that is not one."""
    from accelnav.api import decide_rests

    model = accelnav.load_model(FOOT)
    run, model = accelnav.read_input(_arrays(walk), model)
    own = decide_rests(run, model)
    half = own.mask.copy()
    half[len(half) // 2 :] = False  # only the first half's rests offered
    given = decide_rests(run, model, candidates=half)
    np.testing.assert_array_equal(given.candidates, half)
    rest = accelnav.detect_rests(run, model, candidates=half)
    assert rest.any() and not rest[len(rest) // 2 :].any()
    for bad in (half[:-1], half.astype(int)):
        with pytest.raises(accelnav.UserError, match="rest candidates: an \\(N,\\) bool mask"):
            accelnav.detect_rests(run, model, candidates=bad)
