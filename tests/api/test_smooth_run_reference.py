"""accelnav.smooth_run, the library under ``accelnav smooth``: every axis's smoothed states, standard
deviations and covariances equal the float64 reference filter + RTS smoother's (moved here from the CLI
test, which now checks only what the command adds: its flags and its file)."""

from __future__ import annotations

import numpy as np
from conftest import assert_rel_close

import accelnav
from accelnav.estimate.kf import rts_smooth, run_filter
from accelnav.model.design import axis_design


def test_smooth_run_matches_reference():
    model = accelnav.load_model(None)
    run = accelnav.smooth_run(accelnav.simulate(model, "stop_and_go", 40.0, seed=9), model)
    for j in range(2):
        d = axis_design(model, j)
        f = run_filter(d, run["accel"][:, j], valid=~run["clipped"][:, j])
        s = rts_smooth(d, f)
        sd = np.sqrt(np.einsum("kii->ki", s.P))
        assert_rel_close(run["smooth_x"][j], s.x, sd, 1e-9, "smooth_x")
        assert_rel_close(run["smooth_sd"][j], sd, sd, 1e-9, "smooth_sd")
        assert_rel_close(run["smooth_P"][j], s.P, sd[:, :, None] * sd[:, None, :], 1e-9, "smooth_P")
    assert not run["zupt"].any() and run["fixes"].shape == (0, 4)
