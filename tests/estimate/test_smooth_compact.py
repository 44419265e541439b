"""The plain smoother's fast kernels against their references, bit for bit:

* the compact output written at float32 by the r, u kernel equals the full output's doubles cast by numpy;
* the smoothed (a, eps) covariance, whose steps the kernels skip once it reaches its fixed point on the
  steady rows, equals the step taken at every sample (a plain-Python replay of acn_chunk_bwd_lean's
  operations in their order), through chunk edges before, at and after the steady row.
"""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.estimate import chunked
from accelnav.estimate import fastsmooth as fs
from accelnav.model.design import axis_design
from accelnav.model.edit import with_axis_bias, with_noise
from accelnav.model.load import load_model

pytestmark = pytest.mark.usefixtures("own_steady_cache")


@pytest.fixture(scope="module")
def settles():
    """The default model with a 0.5 s bias time constant: its steady rows settle within ~1 200 samples."""
    m = load_model()
    for ax in m.axes:
        m = with_axis_bias(m, ax.name, ax.c1, ax.c2, 0.5)
    return with_noise(m, sigma_eps=0.05)


def _record(model, n, invalid: bool, seed=7):
    rng = np.random.default_rng(seed)
    k = len(model.axes)
    t = np.arange(n) / model.rate_hz
    accel = np.cumsum(rng.normal(0, 0.05, (n, k)), axis=0)
    clipped = np.zeros((n, k), dtype=bool)
    if invalid:
        clipped[n // 3 : n // 3 + 7, 0] = True
        accel[0, -1] = accel[n - 1, -1] = np.nan
    return t, accel, clipped


def _smooth(model, n, tmp_path, name, invalid=False, stages=("smooth",), info=None, **kw):
    t, accel, clipped = _record(model, n, invalid)
    out = tmp_path / f"{name}.npz"
    got = chunked.smooth_bounded(model, n, chunked.array_reader(t, accel, clipped), out, stages=stages, **kw)
    if info is not None:
        info.update(got)
    with np.load(out) as f:
        return {k: f[k] for k in f.files}


def _replayed_cov(rows: np.ndarray, n: int) -> np.ndarray:
    """The smoothed (P_aa, P_ae, P_ee) of an all-valid run of n samples, one step a sample (bwd_ae_cov's
    operations in C's order: Python's floats are the same doubles)."""
    nt = len(rows)
    row = rows[min(n - 1, nt - 1)]
    saa, sae, see = float(row[11]), float(row[12]), float(row[13])
    out = np.empty((n, 3))
    out[n - 1] = saa, sae, see
    for k in range(n - 2, -1, -1):
        sr, sn = rows[min(k, nt - 1)].tolist(), rows[min(k + 1, nt - 1)].tolist()
        c00, c01, c10, c11 = sr[4:8]
        daa, dae, dee = saa - sn[8], sae - sn[9], see - sn[10]
        t00, t01 = c00 * daa + c01 * dae, c00 * dae + c01 * dee
        t10, t11 = c10 * daa + c11 * dae, c10 * dae + c11 * dee
        saa = sr[11] + t00 * c00 + t01 * c01
        sae = sr[12] + t00 * c10 + t01 * c11
        see = sr[13] + t10 * c10 + t11 * c11
        out[k] = saa, sae, see
    return out


@pytest.mark.parametrize("chunk", [None, 997, 2])
def test_the_skipped_covariance_steps_give_the_doubles_of_every_step(settles, tmp_path, chunk):
    n = 4000
    rows = [fs.steady_gains(axis_design(settles, j)).rows for j in range(len(settles.axes))]
    nt = len(rows[0])
    assert nt < n // 2, "the test needs the steady rows settled inside the run"
    full = _smooth(settles, n, tmp_path, "full", full=True, chunk=chunk)
    for j in range(len(settles.axes)):
        ref = _replayed_cov(rows[j], n)
        # settled from the run's end back to the steady row (else the kernels skip nothing here)
        assert np.all(ref[nt - 1 : n // 2] == ref[n // 2]), "the fixed point is not reached on the steady rows"
        sd = full["smooth_sd"][j]
        np.testing.assert_array_equal(sd[: n - 1, 2], np.sqrt(ref[: n - 1, 0]), f"sd a, axis {j}")
        np.testing.assert_array_equal(sd[: n - 1, 3], np.sqrt(ref[: n - 1, 2]), f"sd eps, axis {j}")


@pytest.mark.parametrize("stages", [("smooth",), ("filt",), ("filt", "smooth")])
@pytest.mark.parametrize("invalid", [False, True])
@pytest.mark.parametrize("chunk", [None, 997, 5, 2])
def test_the_compact_output_is_the_full_doubles_cast_to_float32(settles, tmp_path, chunk, invalid, stages):
    """All valid (the lean kernels throughout) and with clipped and NaN samples (the full store after them); the
    filter's and the smoother's states; the run's first and last states (the summary line's) the same too."""
    n = 3001
    for j in range(len(settles.axes)):
        fs.steady_gains(axis_design(settles, j))
    got_full, got_compact = {}, {}
    full = _smooth(settles, n, tmp_path, "full", invalid, stages, got_full, full=True, chunk=chunk)
    compact = _smooth(settles, n, tmp_path, "compact", invalid, stages, got_compact, full=False, chunk=chunk)
    for key in [f"{st}_{q}" for st in stages for q in ("x", "sd")]:
        assert compact[key].dtype == np.float32 and compact[key].shape == (len(settles.axes), n, 2)
        np.testing.assert_array_equal(compact[key], full[key][..., :2].astype(np.float32), key)
    for end in ("first", "last"):
        assert got_compact[end].keys() == got_full[end].keys()
        for key, v in got_full[end].items():
            np.testing.assert_array_equal(got_compact[end][key], v, f"{end} {key}")


@pytest.mark.parametrize("stages", [("filt",), ("filt", "smooth"), ("smooth",)])
@pytest.mark.parametrize("full", [False, True])
def test_the_filter_on_steady_rows_gives_the_doubles_of_the_per_sample_steps(settles, tmp_path, full, stages):
    """acn_chunk_fwd_steady runs a chunk's samples on the steady row through loops of their own (fwd_on_steady:
    P's r, u rows in locals, the row's terms taken once; means_on_steady: the means alone where the filter's
    states are not wanted) but only strictly inside a chunk: chunks of 2 samples take every sample through the
    per-sample steps (steady_update, predict_ru, the loop's own mean update), the reference, bit for bit."""
    n = 4001
    nt = max(len(fs.steady_gains(axis_design(settles, j)).rows) for j in range(len(settles.axes)))
    assert nt < n // 2, "the test needs most of the run on the steady rows"
    fast = _smooth(settles, n, tmp_path, "fast", stages=stages, full=full)
    each = _smooth(settles, n, tmp_path, "each", stages=stages, full=full, chunk=2)
    for key in [f"{st}_{q}" for st in stages for q in ("x", "sd")]:
        if stages == ("smooth",) and key == "smooth_sd":
            # the last sample's r, u sds are the filter's, from its covariance jumped over the steady samples
            # (steady_jump): one jump or one a chunk round differently, on main too (1e-14 relative)
            np.testing.assert_array_equal(fast[key][:, :-1], each[key][:, :-1], key)
            np.testing.assert_allclose(fast[key][:, -1], each[key][:, -1], rtol=1e-12, atol=0, err_msg=key)
        else:
            np.testing.assert_array_equal(fast[key], each[key], key)
