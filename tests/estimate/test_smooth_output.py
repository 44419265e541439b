"""smooth_run / filter_run outputs: what the user asked for, equal to what the object path and the
float64 reference give (the covariances on request, the states and sds by default)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_rel_close

from accelnav.data.runfile import FORMAT, FORMAT_V1, load_run, save_run
from accelnav.estimate import fastsmooth, zupt
from accelnav.estimate.kf import position_fix, zero_velocity
from accelnav.estimate.pipeline import filter_run, reference_filter_run, smooth_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design


@pytest.fixture(scope="module")
def walk(default_model):
    arrays = simulate(default_model, "stop_and_go", 30.0, 5).to_arrays()
    arrays["clipped"][200:205, 1] = True  # predict-only samples on one axis
    rest = zupt.rest_mask(arrays["accel"], arrays["clipped"], default_model)
    assert 0.1 < rest.mean() < 0.9
    t = arrays["t"]
    fixes = [[position_fix(k, arrays["r"][k, j] + 0.1, 0.5) for k in (2900, 100, 1500)] for j in range(2)]
    return arrays, rest, fixes, t


def _object_path(arrays, model, fixes, rest, params, sigma=None):
    """What smooth_run computed before the arrays: one Measurement per update, unpack, np.stack."""
    out = {k: [] for k in ("filt_x", "filt_P", "filt_x_prior", "filt_P_prior", "smooth_x", "smooth_P")}
    for j in range(len(arrays["axis_names"])):
        ks = zupt.update_samples(rest, model, params)
        sd = [params.sigma if sigma is None or not np.isfinite(sigma[k, j]) else sigma[k, j] for k in ks]
        extras = list(fixes[j]) + [zero_velocity(int(k), s) for k, s in zip(ks, sd, strict=True)]
        res = fastsmooth.smooth(
            axis_design(model, j), arrays["accel"][:, j], valid=~arrays["clipped"][:, j], extras=extras,
            gates=[0.0] * len(extras),
        )  # fmt: skip
        for key, v in (("filt_x", res.x_post), ("filt_x_prior", res.x_prior), ("smooth_x", res.xs)):
            out[key].append(v)
        for key, v in (("filt_P", res.P_post), ("filt_P_prior", res.P_prior), ("smooth_P", res.Ps)):
            out[key].append(fastsmooth.unpack(v))
    return {k: np.stack(v) for k, v in out.items()}


@pytest.mark.parametrize("aids", ["plain", "rests", "rests+fixes", "rests+sigma"])
def test_arrays_path_equals_object_path(walk, default_model, aids):
    arrays, rest, fixes, _ = walk
    params = zupt.resolved(default_model, zupt.ZuptParams(every_s=0.02 if aids == "rests" else 0.0))
    fx = fixes if "fixes" in aids else None
    rs = rest if aids != "plain" else np.zeros(len(rest), dtype=bool)
    sigma = None
    if aids == "rests+sigma":
        sigma = np.full((len(rest), 2), np.nan)
        sigma[: len(rest) // 2] = 0.05
    ref = _object_path(arrays, default_model, fx or [[], []], rs, params, sigma)
    got = smooth_run(
        arrays, default_model, fixes=fx, rest=rs if aids != "plain" else None, zupt_params=params, rest_sigma=sigma
    )
    for key, v in ref.items():
        np.testing.assert_allclose(got[key], v, rtol=1e-12, atol=1e-12 * np.abs(v).max(), err_msg=key)
    sd = np.sqrt(np.einsum("akii->aki", ref["smooth_P"]))
    assert np.array_equal(got["smooth_sd"], sd)  # the same numbers, the same square roots
    if aids != "plain":
        assert got["zupt"].any() and len(got["zupt_nis"])


def test_default_output_is_states_and_sds(walk, default_model):
    arrays, rest, _, _ = walk
    full = smooth_run(arrays, default_model, rest=rest)
    lean = smooth_run(arrays, default_model, rest=rest, covariances=False)
    assert not {"filt_P", "smooth_P", "filt_x_prior", "filt_P_prior"} & set(lean)
    for key in ("filt_x", "filt_sd", "smooth_x", "smooth_sd", "zupt", "zupt_nis"):
        assert np.array_equal(lean[key], full[key]), key


def test_update_samples_matches_a_loop_over_the_rests(default_model):
    rng = np.random.default_rng(3)
    mask = rng.random(5000) < 0.7  # many short rests, some of one sample
    for every_s in (0.0, 0.01, 0.03, 0.5):
        p = zupt.ZuptParams(every_s=every_s)
        step = max(1, round(every_s * default_model.rate_hz))
        loop = [k for a, b in zupt.intervals(mask) for k in range(a, b, step)]
        assert zupt.update_samples(mask, default_model, p).tolist() == loop


def test_compiled_filter_equals_the_reference(walk, default_model):
    arrays = walk[0]
    ref = reference_filter_run(arrays, default_model)
    got = filter_run(arrays, default_model)
    for j in range(2):
        sd = np.sqrt(np.einsum("kii->ki", ref["filt_P"][j]))
        assert_rel_close(got["filt_x"][j], ref["filt_x"][j], sd, 1e-9, "filt_x")
        assert_rel_close(got["filt_sd"][j], sd, sd, 1e-9, "filt_sd")
        assert_rel_close(got["filt_P"][j], ref["filt_P"][j], sd[:, :, None] * sd[:, None, :], 1e-9, "filt_P")
        sdp = np.sqrt(np.einsum("kii->ki", ref["filt_P_prior"][j]))
        assert_rel_close(got["filt_x_prior"][j], ref["filt_x_prior"][j], sdp, 1e-9, "filt_x_prior")


def test_run_file_versions(tmp_path, walk, default_model):
    arrays = {k: walk[0][k] for k in ("t", "axis_names", "accel", "clipped")}
    full = smooth_run(arrays, default_model)
    save_run(tmp_path / "full.npz", full, default_model)
    lean = {k: v for k, v in full.items() if not k.endswith(("_P", "_prior"))}
    save_run(tmp_path / "lean.npz", lean, default_model, compress=True)
    a1, _ = load_run(tmp_path / "full.npz")
    a2, _ = load_run(tmp_path / "lean.npz")
    assert str(a1["format"]) == FORMAT_V1 and str(a2["format"]) == FORMAT  # /1 while it holds what /1 promised
    old = {k: v for k, v in a1.items() if not k.endswith("_sd")}  # a file of an older accelnav
    save_run(tmp_path / "old.npz", old, default_model)
    a0, _ = load_run(tmp_path / "old.npz")
    for key in ("filt_sd", "smooth_sd"):
        assert np.array_equal(a0[key], full[key]) and np.array_equal(a2[key], full[key])


def _fixes_row_by_row(rows, t, axis_names):
    """read_fixes' placement as it was, one row at a time: the oracle of the array version."""
    n, Ts = len(t), float(np.median(np.diff(t)))
    per_axis = [[] for _ in axis_names]
    for ts, ax, r, s in rows:
        k = int(np.clip(np.searchsorted(t, ts), 1, max(n - 1, 1)))
        if n > 1 and abs(t[k - 1] - ts) <= abs(t[k] - ts):
            k -= 1
        per_axis[axis_names.index(ax)].append(position_fix(min(k, n - 1), r, s))
    assert all(t[0] - Ts / 2 <= ts <= t[-1] + Ts / 2 for ts, *_ in rows)
    return per_axis


def test_fixes_read_as_arrays_land_where_row_by_row_did(tmp_path):
    from accelnav.errors import UserError
    from accelnav.estimate.fixes import read_fixes

    t = np.arange(1000) * 0.01 + 3.0
    rng = np.random.default_rng(4)
    ts = np.concatenate((rng.uniform(t[0] - 0.005, t[-1] + 0.005, 300), t[:5] + 0.005, [t[0] - 0.005, t[-1] + 0.005]))
    rows = [(float(x), "xy"[i % 2], float(rng.normal()), float(rng.uniform(0.1, 2))) for i, x in enumerate(ts)]
    path = tmp_path / "fixes.csv"
    path.write_text("time_s,axis,position_m,sigma_m\n" + "".join(f"{a!r},{b},{c!r},{d!r}\n" for a, b, c, d in rows))
    assert read_fixes(path, t, ["x", "y"]) == _fixes_row_by_row(rows, t, ["x", "y"])
    # the first bad row, with its first fault
    lines = path.read_text().splitlines()
    lines[40] = f"{t[-1] + 1},z,1.0,-1"
    lines[90] = f"{t[-1] + 1},x,1.0,1"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(UserError, match=r"row 41: axis 'z'; accepted: x, y"):
        read_fixes(path, t, ["x", "y"])
    lines[40] = f"{t[-1] + 1},x,1.0,-1"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(UserError, match=r"row 41: sigma_m is -1"):
        read_fixes(path, t, ["x", "y"])
    lines[40] = f"{t[0]},x,1.0,1"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(UserError, match=r"row 91: time_s 13\.99 is outside the run"):
        read_fixes(path, t, ["x", "y"])
