"""A simulated vehicle whose bias wanders STIFF times faster than the shipped model says, with 1 Hz position
fixes: the case of issue 23 (a), shared by the library's consistency tests (tests/estimate) and the smooth
command's messages about it (tests/cli)."""

from __future__ import annotations

import numpy as np

from accelnav.data.runfile import save_run
from accelnav.estimate.kf import position_fix
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.edit import with_noise
from accelnav.model.load import load_model

STIFF = 30.0
FIX_SIGMA = 0.5


def vehicle_case():
    """(run arrays, shipped model, the right model, per-axis fixes)."""
    shipped = load_model(None)
    right = with_noise(shipped, sigma_eps=shipped.noise.sigma_eps * STIFF)
    run = simulate(right, "vehicle", 60.0, 4).to_arrays()
    rng = np.random.default_rng(1)
    step = int(round(shipped.rate_hz))  # 1 Hz
    fixes = [
        [
            position_fix(k, run["r"][k, j] + FIX_SIGMA * rng.standard_normal(), FIX_SIGMA)
            for k in range(0, len(run["t"]), step)
        ]
        for j in range(len(run["axis_names"]))
    ]
    return run, shipped, right, fixes


def rms_vs_truth(run, est) -> float:
    return float(np.sqrt(np.mean((np.asarray(est) - run["r"].T) ** 2)))


def write_files(tmp_path, run, model, fixes):
    """The run file and the fixes CSV the command reads: (run path, fixes path)."""
    path = tmp_path / "veh.npz"
    save_run(path, run, model)
    fx_csv = tmp_path / "fixes.csv"
    rows = ["time_s,axis,position_m,sigma_m"]
    for j, fx in enumerate(fixes):
        rows += [f"{float(run['t'][m.k])!r},{run['axis_names'][j]},{m.z!r},{float(np.sqrt(m.R))!r}" for m in fx]
    fx_csv.write_text("\n".join(rows) + "\n")
    return path, fx_csv
