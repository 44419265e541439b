"""The example recording the package ships (``accelnav.example_path("walk.csv")``): 20 s of the simulator's
walking scenario for the foot_imu model, written as a phone app writes it (a millisecond clock, g, level
axes with gravity removed), with three position fixes per axis taken from the simulated truth.

Run as a program to write them again: ``python tests/support/example_walk.py models/examples``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import accelnav
from accelnav.resources import models_dir

G0 = 9.80665
SECONDS, SEED = 20.0, 7
FIX_SIGMA_M = 0.05


def walk():
    """The simulated run: truth and accelerations."""
    return accelnav.simulate(accelnav.load_model(models_dir() / "foot_imu.toml"), "walking", SECONDS, SEED)


def fix_samples(n: int) -> list[int]:
    """Where the fixes are: the first, the middle and the last sample."""
    return [0, n // 2, n - 1]


def write(folder: Path) -> None:
    sim = walk()
    rows = ["t_ms,acc_x_g,acc_y_g"]
    rows += [f"{1e3 * t:.0f},{a / G0:.6f},{b / G0:.6f}" for t, (a, b) in zip(sim["t"], sim["accel"], strict=True)]
    (folder / "walk.csv").write_text("\n".join(rows) + "\n")
    fixes = ["time_s,position_m,sigma_m,axis"]
    fixes += [
        f"{sim['t'][k]:.3f},{sim['r'][k, j]:.4f},{FIX_SIGMA_M},{ax}"
        for k in fix_samples(len(sim["t"]))
        for j, ax in enumerate("xy")
    ]
    (folder / "walk_fixes.csv").write_text("\n".join(fixes) + "\n")


if __name__ == "__main__":
    write(Path(sys.argv[1]))
