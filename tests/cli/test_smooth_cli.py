"""accelnav smooth: fixes, automatic and file zero-velocity updates, plots, refusals of bad files."""

from __future__ import annotations

import numpy as np
import pytest
from support.cli import run_cli as _run

import accelnav
from accelnav.cli import main
from accelnav.data.runfile import load_run


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    path = tmp_path_factory.mktemp("smooth") / "sim.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "40", "--seed", "9", "--out", str(path)]) == 0
    return path


@pytest.mark.parametrize("flags", [[], ["--covariances"]], ids=["states-and-sds", "covariances"])
def test_plain_smooth_writes_the_library_result(sim, tmp_path, capsys, flags):
    """The file holds accelnav.smooth_run's result (checked against the reference in
    tests/api/test_smooth_run_reference.py); the covariances only on request."""
    status, out, _ = _run(["smooth", sim, "--out", tmp_path / "s.npz", "--full", *flags], capsys)
    assert status == 0
    arrays, model = load_run(tmp_path / "s.npz")
    assert ("smooth_P" in arrays) == bool(flags)  # the covariances only on request
    lib = accelnav.smooth_run(load_run(sim)[0], model)
    for key in ("smooth_x", "smooth_sd", *(["smooth_P"] if flags else [])):
        np.testing.assert_array_equal(arrays[key], lib[key], err_msg=key)
    assert not arrays["zupt"].any() and arrays["fixes"].shape == (0, 4)


def test_fixes_and_auto_zupt_with_plots(sim, tmp_path, capsys):
    arrays, _ = load_run(sim)
    t, r = arrays["t"], arrays["r"]
    rows = ["time_s,axis,position_m,sigma_m"]
    for k in (1000, 2500, 3999):
        rows += [f"{t[k] + 0.002:.4f},x,{r[k, 0]:.6f},0.05", f"{t[k]:.4f},y,{r[k, 1]:.6f},0.05"]
    (tmp_path / "fixes.csv").write_text("\n".join(rows) + "\n")
    argv = ["smooth", sim, "--fixes", tmp_path / "fixes.csv", "--zupt", "auto", "--out", tmp_path / "s.npz"]
    status, out, _ = _run([*argv, "--plots", tmp_path / "plots"], capsys)
    assert status == 0 and "zero-velocity detector" in out and "position fixes per axis: 3, 3" in out
    out_arrays, _ = load_run(tmp_path / "s.npz")
    assert out_arrays["zupt"].sum() > 100 and out_arrays["fixes"].shape == (6, 4)
    # the fix at k pins the smoothed position there
    for k in (1000, 2500):
        assert abs(out_arrays["smooth_x"][0, k, 0] - r[k, 0]) < 0.1
    for name in ("smooth.png", "fig10_bias.png", "fig11_position_filter.png", "fig12_position_smoother.png"):
        assert (tmp_path / "plots" / name).stat().st_size > 10_000


def test_zupt_from_file_is_applied_without_gate(sim, tmp_path, capsys):
    (tmp_path / "rest.csv").write_text("start_s,end_s\n0,1.5\n10,10.2\n")
    status, out, _ = _run(["smooth", sim, "--zupt", tmp_path / "rest.csv", "--out", tmp_path / "s.npz"], capsys)
    assert status == 0
    arrays, _ = load_run(tmp_path / "s.npz")
    # 0..1.5 s -> samples 0..150: 151; 10..10.2 s -> 1000..1020: 21 (an update at every sample by default)
    assert arrays["zupt"][:, 0].sum() == 172 and arrays["zupt"][:, 1].sum() == 172
    status, out, _ = _run(["smooth", sim, "--zupt", tmp_path / "rest.csv", "--zupt-every", "0.1", "--out",
                           tmp_path / "s.npz"], capsys)  # fmt: skip
    arrays, _ = load_run(tmp_path / "s.npz")
    # every 10th: 16 and 3
    assert arrays["zupt"][:, 0].sum() == 19 and arrays["zupt"][:, 1].sum() == 19


@pytest.mark.parametrize(
    "text,words",
    [
        ("", "empty"),
        ("time_s,position_m\n1,2\n", "missing column 'sigma_m'"),
        ("time_s,axis,position_m,sigma_m,colour\n1,x,2,3,red\n", "unknown column 'colour'"),
        ("time_s,axis,position_m,sigma_m\n", "no data rows"),
        ("time_s,axis,position_m,sigma_m\n1,x,abc,0.1\n", "row 2: position_m is 'abc'"),
        ("time_s,axis,position_m,sigma_m\n1,x,1,0\n", "row 2: sigma_m is 0"),
        ("time_s,axis,position_m,sigma_m\n1,z,1,0.1\n", "row 2: axis 'z'"),
        ("time_s,axis,position_m,sigma_m\n99,x,1,0.1\n", "row 2: time_s 99 is outside the run"),
        ("time_s,axis,position_m,sigma_m\n1,x,1\n", "row 2: 3 fields"),
        ("time_s,position_m,sigma_m\n1,1,0.1\n", "add an 'axis' column"),
    ],
)
def test_bad_fixes_files_refused_with_one_line(sim, tmp_path, capsys, text, words):
    (tmp_path / "f.csv").write_text(text)
    status, _, err = _run(["smooth", sim, "--fixes", tmp_path / "f.csv", "--out", tmp_path / "s.npz"], capsys)
    assert status == 2 and words in err and err.count("\n") == 1
    assert not (tmp_path / "s.npz").exists()


def test_bad_zupt_arguments_refused(sim, tmp_path, capsys):
    status, _, err = _run(["smooth", sim, "--zupt", "auto", "--zupt-window", "0", "--out", tmp_path / "s.npz"], capsys)
    assert status == 2 and "window" in err and err.count("\n") == 1
    status, _, err = _run(["smooth", sim, "--zupt", tmp_path / "none.csv", "--out", tmp_path / "s.npz"], capsys)
    assert status == 2 and "none.csv: no such file" in err
    (tmp_path / "r.csv").write_text("start_s,end_s\n5,4\n")
    status, _, err = _run(["smooth", sim, "--zupt", tmp_path / "r.csv", "--out", tmp_path / "s.npz"], capsys)
    assert status == 2 and "end_s 4 is before start_s 5" in err


def test_zupt_file_with_axis_and_sigma_columns(sim, tmp_path, capsys):
    (tmp_path / "rest.csv").write_text("start_s,end_s,axis,sigma\n0,1.5,x,0.001\n10,10.2,y,0.5\n")
    status, _, err = _run(["smooth", sim, "--zupt", tmp_path / "rest.csv", "--out", tmp_path / "s.npz"], capsys)
    assert status == 0, err
    arrays, _ = load_run(tmp_path / "s.npz")
    assert arrays["zupt"][:, 0].sum() == 151 and arrays["zupt"][:, 1].sum() == 21
    assert not arrays["zupt"][1000:1021, 0].any() and arrays["zupt"][1000:1021, 1].all()
    # sigma is honoured: a tight update pins the velocity, a loose one hardly moves it
    assert arrays["smooth_sd"][0, 100, 1] < 0.002
    bad = tmp_path / "bad.csv"
    bad.write_text("start_s,end_s,axis,sigma\n0,1,x,0\n")
    status, _, err = _run(["smooth", sim, "--zupt", bad, "--out", tmp_path / "s.npz"], capsys)
    assert status == 2 and "row 2: sigma is 0" in err and err.count("\n") == 1


@pytest.mark.parametrize("form", ["npz", "csv", "csv_t"])
def test_zupt_as_a_per_sample_mask(sim, tmp_path, capsys, form):
    arrays, _ = load_run(sim)
    n = len(arrays["t"])
    mask = np.zeros(n, dtype=int)
    mask[0:151] = 1
    mask[1000:1021] = 1
    if form == "npz":
        path = tmp_path / "m.npz"
        np.savez(path, rest=mask)
    elif form == "csv":
        path = tmp_path / "m.csv"
        path.write_text("rest\n" + "\n".join(str(v) for v in mask) + "\n")
    else:
        path = tmp_path / "m.csv"
        path.write_text("t_s,rest\n" + "\n".join(f"{t:.3f},{v}" for t, v in zip(arrays["t"], mask, strict=True)) + "\n")
    status, _, err = _run(["smooth", sim, "--zupt", path, "--out", tmp_path / "s.npz"], capsys)
    assert status == 0, err
    out, _ = load_run(tmp_path / "s.npz")
    assert np.array_equal(out["zupt"][:, 0], mask.astype(bool)) and np.array_equal(out["zupt"][:, 1], mask.astype(bool))


def test_bad_masks_refused_in_one_line(sim, tmp_path, capsys):
    (tmp_path / "short.csv").write_text("rest\n1\n0\n")
    status, _, err = _run(["smooth", sim, "--zupt", tmp_path / "short.csv", "--out", tmp_path / "s.npz"], capsys)
    assert status == 2 and "the rest mask has 2 samples; the run has 4000" in err and err.count("\n") == 1
    np.savez(tmp_path / "two.npz", rest=np.full(4000, 2))
    status, _, err = _run(["smooth", sim, "--zupt", tmp_path / "two.npz", "--out", tmp_path / "s.npz"], capsys)
    assert status == 2 and "accepted: 0 or 1" in err and err.count("\n") == 1
