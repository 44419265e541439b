"""filter and smooth of a plain recording stream through the chunked kernels (accelnav.estimate.chunked) and
give the whole-array path's numbers (pipeline.filter_run, smooth_run) to 1e-12, sigma-scaled."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_rel_close

from accelnav.cli import main
from accelnav.data.runfile import load_run
from accelnav.estimate.pipeline import filter_run, smooth_run

RTOL = 1e-12


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    path = tmp_path_factory.mktemp("stream") / "rec.npz"
    rng = np.random.default_rng(2)
    n = 2500
    accel = np.cumsum(rng.normal(0, 0.05, (n, 2)), axis=0)
    keep = np.ones(n, dtype=bool)
    keep[700:703] = False  # a gap (--allow-gaps): predict-only samples, where the steady rows end
    np.savez(path, t=(np.arange(n) / 100.0)[keep], accel=accel[keep])
    return path


def _run(argv, capsys):
    status = main([str(a) for a in argv] + ["--allow-gaps"])
    out = capsys.readouterr()
    return status, out.out, out.err


@pytest.mark.parametrize("flags", [[], ["--filter-states"]])
def test_smooth_streams_and_equals_the_whole_array_path(rec, tmp_path, capsys, flags):
    status, out, err = _run(["smooth", rec, "--out", tmp_path / "s.npz", "--full", *flags], capsys)
    assert status == 0, err
    assert "in bounded memory, streamed" in out and "smoother at start" in out
    got, model = load_run(tmp_path / "s.npz")
    assert got["clipped"][700:703].all() and got["clipped"].sum() == 6  # the gap, filled as predict-only
    ref = smooth_run({k: got[k] for k in ("t", "axis_names", "accel", "clipped")}, model, covariances=False)
    assert ("filt_x" in got) == bool(flags)  # the filter's states only on request
    for key in ("smooth", "filt") if flags else ("smooth",):
        sd = ref[f"{key}_sd"]
        assert_rel_close(got[f"{key}_x"], ref[f"{key}_x"], sd, RTOL, f"{key}_x")
        assert_rel_close(got[f"{key}_sd"], sd, 0.0, RTOL, f"{key}_sd")


def test_filter_streams_and_equals_the_whole_array_path(rec, tmp_path, capsys):
    status, out, err = _run(["filter", rec, "--full", "--out", tmp_path / "f.npz"], capsys)
    assert status == 0, err
    assert "in bounded memory, streamed" in out and "filter at end" in out
    got, model = load_run(tmp_path / "f.npz")
    assert "smooth_x" not in got
    ref = filter_run({k: got[k] for k in ("t", "axis_names", "accel", "clipped")}, model, covariances=False)
    assert_rel_close(got["filt_x"], ref["filt_x"], ref["filt_sd"], RTOL, "filt_x")
    assert_rel_close(got["filt_sd"], ref["filt_sd"], 0.0, RTOL, "filt_sd")
    # the default: r, u and their sds at float32 (24-bit mantissa), nothing else
    status, out, err = _run(["filter", rec, "--out", tmp_path / "c.npz"], capsys)
    assert status == 0, err
    small, _ = load_run(tmp_path / "c.npz")
    assert "accel" not in small and small["filt_x"].dtype == np.float32 and small["filt_x"].shape[-1] == 2
    assert_rel_close(small["filt_x"], ref["filt_x"][..., :2], ref["filt_sd"][..., :2], 2**-23, "filt_x compact")
    assert_rel_close(small["filt_sd"], ref["filt_sd"][..., :2], 0.0, 2**-23, "filt_sd compact")


def test_what_needs_the_whole_arrays_still_gets_them(rec, tmp_path, capsys):
    status, out, err = _run(["smooth", rec, "--out", tmp_path / "c.npz", "--covariances"], capsys)
    assert status == 0, err
    assert "streamed" not in out
    got, _ = load_run(tmp_path / "c.npz")
    assert "smooth_P" in got and "filt_x" in got
