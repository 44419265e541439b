"""smooth --warm-start: a recording that begins long after power-on, its bias already settled at c1 + c2."""

from __future__ import annotations

import numpy as np

from accelnav.cli import main
from accelnav.estimate.pipeline import smooth_run
from accelnav.model.edit import warm_started
from accelnav.model.load import load_model


def _settled_still(model, seconds=120.0, seed=5):
    """A still unit, recorded after its warm-up: z = (c1 + c2) + white noise of variance R, per axis."""
    rng = np.random.default_rng(seed)
    n = int(seconds * model.rate_hz)
    eps = np.array([a.c1 + a.c2 for a in model.axes])
    accel = eps + rng.normal(0.0, np.sqrt(model.noise.R), (n, len(model.axes)))
    t = np.arange(n) / model.rate_hz
    names = np.array([a.name for a in model.axes])
    return {"t": t, "axis_names": names, "accel": accel, "clipped": np.zeros(accel.shape, dtype=bool)}


def test_warm_started_model_keeps_the_bias_fixed_point():
    m = load_model()
    w = warm_started(m)
    for a, b in zip(m.axes, w.axes, strict=True):
        assert (b.c1, b.c2, b.T) == (0.0, a.c1 + a.c2, a.T)


def test_warm_start_prior_is_the_settled_bias_and_the_position_drifts_less():
    m = load_model()  # c1 = 0.08 and -0.05 m/s^2: a cold prior is off by that much
    arrays = _settled_still(m)
    cold = smooth_run(dict(arrays), m, covariances=True)
    warm = smooth_run(dict(arrays), m, covariances=True, warm_start=True)
    settled = np.array([a.c1 + a.c2 for a in m.axes])
    np.testing.assert_allclose(warm["filt_x_prior"][:, 0, 3], settled)
    np.testing.assert_allclose(cold["filt_x_prior"][:, 0, 3], [a.c2 for a in m.axes])
    # truth: still, r = 0; the filter's position after two minutes
    cold_r = np.abs(cold["filt_x"][:, -1, 0])
    warm_r = np.abs(warm["filt_x"][:, -1, 0])
    assert np.all(warm_r < cold_r), (warm_r, cold_r)


def test_smooth_warm_start_flag(tmp_path, capsys):
    m = load_model()
    arrays = _settled_still(m, 60.0)
    cols = {"t": arrays["t"], **{f"acc_{n}_m_s2": arrays["accel"][:, j] for j, n in enumerate("xy")}}
    path = tmp_path / "still.csv"
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    ends = []
    for extra in ([], ["--warm-start"]):
        out = tmp_path / f"o{len(extra)}.npz"
        assert main(["smooth", str(path), "--out", str(out), "--full", *extra]) == 0, capsys.readouterr().err
        with np.load(out) as z:  # the smoother's last sample is the filter's, exactly
            ends.append(np.abs(z["smooth_x"][:, -1, 0]))
    assert np.all(ends[1] < ends[0]), ends
