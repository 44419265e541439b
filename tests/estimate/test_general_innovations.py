"""Issue 24: the aids' NIS from the innovations the compiled filter met, not from a replay of the filter.

smooth_run's ``fix_nis`` and ``zupt_nis`` are y^2 / S of every applied aid. They now come out of
acn_general itself; the replay from the priors (accelnav.estimate.consistency.aid_innovations, which
the pipeline ran over every zero-velocity update: 40 % of ``smooth --zupt auto`` at 1e6 samples) stays
the oracle: same numbers to 1e-12, fixes and rests on every axis.
"""

from __future__ import annotations

import numpy as np

from accelnav.estimate import zupt
from accelnav.estimate.consistency import aid_innovations
from accelnav.estimate.kf import Aids, position_fix
from accelnav.estimate.pipeline import smooth_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.design import axis_design


def test_nis_equals_the_replay_of_the_filter(default_model):
    run = simulate(default_model, "stop_and_go", 60.0, seed=5).to_arrays()
    n = len(run["t"])
    rest = np.abs(run["u"][:, 0]) < 1e-9
    fixes = [[position_fix(k, float(run["r"][k, j]) + 0.3, 0.5) for k in range(150, n, 700)] for j in range(2)]
    params = zupt.ZuptParams()
    out = smooth_run(run, default_model, fixes=fixes, rest=rest, zupt_params=params)
    zn = out["zupt_nis"]
    assert len(out["fix_nis"]) == sum(map(len, fixes)) and len(zn) > 1000
    seen = 0
    for j in range(2):
        d = axis_design(default_model, j)
        za = zupt.axis_aids(rest, None, default_model, params)
        applied = out["zupt"][za.k, j]
        used = Aids.of(fixes[j]).concat(za.take(np.flatnonzero(applied)))
        z, valid = run["accel"][:, j], ~run["clipped"][:, j]
        y, S = aid_innovations(d, z, valid, out["filt_x_prior"][j], out["filt_P_prior"][j], used.measurements())
        want = y * y / S
        nf = len(fixes[j])
        np.testing.assert_allclose(out["fix_nis"][seen : seen + nf], want[:nf], rtol=1e-12)
        np.testing.assert_allclose(zn[zn[:, 1] == j, 2], want[nf:], rtol=1e-12)
        seen += nf


def test_nis_bounds_are_the_chi2_quantiles():
    """nis_check's bounds come from scipy.special (a tenth of scipy.stats' import time): the same numbers."""
    from scipy import stats

    from accelnav.estimate.consistency import NIS_QUANTILE, nis_check

    for n in (1, 2, 7, 100, 12_345, 10**6):
        c = nis_check("rests", np.ones(n))
        np.testing.assert_allclose(c.low * n, stats.chi2.ppf(1 - NIS_QUANTILE, n), rtol=1e-12)
        np.testing.assert_allclose(c.high * n, stats.chi2.ppf(NIS_QUANTILE, n), rtol=1e-12)
