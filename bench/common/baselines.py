"""Baselines shared by the benchmark scripts: the public smoothers we compare against, and a timer.

FilterPy's rts_smoother predicts with F x alone and ignores the forcing term
b, so it runs on the exactly equivalent shifted problem eps - (c1 + c2);
pykalman applies b (transition_offsets) in both passes.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np


def best_of(fn, repeat: int) -> float:
    """Shortest wall time of ``repeat`` calls of fn(), s."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def filterpy_smooth(d, z):
    """FilterPy batch_filter + rts_smoother over accelerations z; smoothed (N, 4)."""
    from filterpy.kalman import KalmanFilter

    mu = d.eps_mean
    kf = KalmanFilter(dim_x=4, dim_z=1)
    kf.x = (d.x0 - [0, 0, 0, mu]).reshape(4, 1)
    kf.P, kf.F, kf.Q, kf.H, kf.R = np.array(d.P0), np.array(d.F), np.array(d.Q), np.array(d.H), np.array([[d.R]])
    xs, Ps, _, _ = kf.batch_filter((z - mu).reshape(-1, 1), update_first=True)
    x, _, _, _ = kf.rts_smoother(xs, Ps)
    return x.reshape(-1, 4) + [0, 0, 0, mu]


def pykalman_smooth(d, z):
    """pykalman's smooth over accelerations z; smoothed (N, 4)."""
    from pykalman import KalmanFilter

    kf = KalmanFilter(
        transition_matrices=np.array(d.F),
        observation_matrices=np.array(d.H),
        transition_covariance=np.array(d.Q),
        observation_covariance=np.array([[d.R]]),
        transition_offsets=np.array(d.b),
        observation_offsets=np.zeros(1),
        initial_state_mean=np.array(d.x0),
        initial_state_covariance=np.array(d.P0),
    )
    return kf.smooth(z.reshape(-1, 1))[0]


def builds(baseline: Path) -> dict[str, str]:
    """{"this": this interpreter, "baseline": the .venv python of the checkout ``baseline``, if it has one}:
    a before/after pair run by one bench on the same data."""
    out = {"this": sys.executable}
    base_py = baseline / ".venv" / "bin" / "python"
    if base_py.exists():
        out["baseline"] = str(base_py)
    else:
        print(f"no baseline: {base_py} is absent")
    return out
