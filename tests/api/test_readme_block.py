"""README's "From Python" block, exactly as printed there, against the installed wheel from an empty folder."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import MODELS, REPO

import accelnav

G0 = 9.80665


def _block() -> str:
    readme = (REPO / "README.md").read_text()
    section = readme.split("## From Python", 1)[1].split("\n## ", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    return code


def _inputs(folder) -> np.ndarray:
    """What the block reads: the user's model, a phone-style CSV (ms clock, g) and three fixes per axis."""
    model = accelnav.load_model(MODELS / "foot_imu.toml")
    (folder / "my_phone.toml").write_text(model.text)
    walk = accelnav.simulate(model, "walking", 30.0, 7)
    rows = ["t_ms,acc_x_g,acc_y_g"]
    rows += [f"{1e3 * t:.3f},{a / G0:.9f},{b / G0:.9f}" for t, (a, b) in zip(walk.t, walk.accel, strict=True)]
    (folder / "walk.csv").write_text("\n".join(rows) + "\n")
    ks = [0, len(walk.t) // 2, len(walk.t) - 1]
    (folder / "fixes.csv").write_text(
        "time_s,position_m,sigma_m,axis\n"
        + "".join(f"{walk.t[k]:.3f},{walk['r'][k, j]:.6f},0.05,{ax}\n" for k in ks for j, ax in enumerate("xy"))
    )
    return walk["r"]


def test_the_readme_block_runs_from_an_empty_folder_against_the_wheel(wheel, tmp_path):
    pytest.importorskip("pandas")  # the block ends in a DataFrame
    _, _, site = wheel
    work = tmp_path / "work"
    work.mkdir()
    truth = _inputs(work)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ACCELNAV_CACHE_DIR")}
    env.update(PYTHONPATH=str(site), ACCELNAV_CACHE_DIR=str(tmp_path / "cache"), MPLBACKEND="Agg")
    code = f"import accelnav; assert accelnav.__file__.startswith({str(site)!r}), accelnav.__file__\n" + _block()
    done = subprocess.run([sys.executable, "-c", code], cwd=work, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    # the last smoothed positions it prints are the checkout's own, and the final fixes hold them to the truth
    printed = dict(re.findall(r"^([xy]_smooth_r)\s+(\S+)$", done.stdout, flags=re.M))
    assert set(printed) == {"x_smooth_r", "y_smooth_r"}, done.stdout
    cwd = os.getcwd()
    try:
        os.chdir(work)
        run, model = accelnav.read_input("walk.csv", accelnav.load_model("my_phone.toml"))
        run = accelnav.smooth_run(run, model, rest=accelnav.detect_rests(run, model), fixes="fixes.csv")
    finally:
        os.chdir(cwd)
    last = run.position()[-1]
    sd = np.sqrt(run["smooth_P"][:, -1, 0, 0])
    for j, name in enumerate(("x_smooth_r", "y_smooth_r")):
        assert float(printed[name]) == pytest.approx(last[j], rel=1e-5, abs=1e-9)
        assert abs(last[j] - truth[-1, j]) <= 4 * sd[j]
