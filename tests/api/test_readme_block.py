"""README's "From Python" block, exactly as printed there, against the installed wheel from an empty folder."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO
from support import example_walk

import accelnav

G0 = 9.80665


def _block() -> str:
    readme = (REPO / "README.md").read_text()
    section = readme.split("## From Python", 1)[1].split("\n## ", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    return code


def test_the_readme_block_runs_from_an_empty_folder_against_the_wheel(wheel, tmp_path):
    """Nothing but the block: the model and the recording it reads are the wheel's own (accelnav.example_path)."""
    pytest.importorskip("pandas")  # the block ends in a DataFrame
    _, _, site = wheel
    work = tmp_path / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ACCELNAV_CACHE_DIR")}
    env.update(PYTHONPATH=str(site), ACCELNAV_CACHE_DIR=str(tmp_path / "cache"), MPLBACKEND="Agg")
    code = f"import accelnav; assert accelnav.__file__.startswith({str(site)!r}), accelnav.__file__\n" + _block()
    done = subprocess.run([sys.executable, "-c", code], cwd=work, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    assert list(work.iterdir()) == []  # it needed no file of the reader's, and left none
    # the last smoothed positions it prints are the checkout's own, and the final fixes hold them to the truth
    printed = dict(re.findall(r"^([xy]_smooth_r)\s+(\S+)$", done.stdout, flags=re.M))
    assert set(printed) == {"x_smooth_r", "y_smooth_r"}, done.stdout
    model = accelnav.load_model(accelnav.example_path("foot_imu.toml"))
    run, model = accelnav.read_input(accelnav.example_path("walk.csv"), model)
    run = accelnav.smooth_run(
        run, model, rest=accelnav.detect_rests(run, model), fixes=accelnav.example_path("walk_fixes.csv")
    )
    last = run.position()[-1]
    sd = np.sqrt(run["smooth_P"][:, -1, 0, 0])
    truth = example_walk.walk()["r"][-1]
    for j, name in enumerate(("x_smooth_r", "y_smooth_r")):
        assert float(printed[name]) == pytest.approx(last[j], rel=1e-5, abs=1e-9)
        assert abs(last[j] - truth[j]) <= 4 * sd[j]


def test_the_shipped_walk_is_what_the_readme_says(tmp_path):
    """t_ms, acc_x_g, acc_y_g at 200 Hz, level and gravity-free: the simulator's walk written as
    tests/support/example_walk.py writes it (run it again if the simulator changes)."""
    shipped = accelnav.example_path("walk.csv")
    assert shipped.read_text().split("\n", 1)[0] == "t_ms,acc_x_g,acc_y_g"
    data = np.loadtxt(shipped, delimiter=",", skiprows=1)
    assert np.allclose(np.diff(data[:, 0]), 5.0)  # 200 Hz in milliseconds
    sim = example_walk.walk()
    assert np.abs(data[:, 1:] - sim["accel"] / G0).max() <= 0.5e-6 * (1 + 1e-6)  # rounded to six decimals of g
    assert np.all(np.abs(np.median(data[:, 1:], axis=0)) < 0.05)  # no axis carries gravity (1 g)
    example_walk.write(tmp_path)
    assert (tmp_path / "walk_fixes.csv").read_text() == accelnav.example_path("walk_fixes.csv").read_text()


def test_an_example_not_shipped_is_refused_with_the_names():
    with pytest.raises(accelnav.UserError, match=r"example 'run\.csv': not shipped; accepted: .*walk\.csv"):
        accelnav.example_path("run.csv")
