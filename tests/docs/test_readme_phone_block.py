"""README's "From a phone" block, exactly as printed there, from an empty folder: a phone logger's export read,
levelled and smoothed in three lines, ending where the shipped export's phone moved (tests/support/phone_logs.py)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import zipfile

import numpy as np
from conftest import REPO
from support import phone_logs as pl

import accelnav


def _block() -> str:
    section = (REPO / "README.md").read_text().split("## From a phone", 1)[1].split("\n## ", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    return code


def test_the_phone_block_runs_in_three_lines_to_the_move(tmp_path):
    code = _block()
    assert len([line for line in code.splitlines() if line.strip()]) == 3
    env = dict(os.environ, ACCELNAV_CACHE_DIR=str(tmp_path / "cache"), MPLBACKEND="Agg")
    work = tmp_path / "work"
    work.mkdir()
    probe = code + "print(*run.position()[-1])\n"
    done = subprocess.run([sys.executable, "-c", probe], cwd=work, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert list(work.iterdir()) == []
    end = np.array([float(v) for v in done.stdout.split()[-2:]])
    np.testing.assert_allclose(end, pl.MOVE, atol=0.03)  # metres, of a 1.1 m move


def test_the_shipped_export_is_the_simulated_phone():
    """phone_move.zip holds phone_logs' phone in Sensor Logger's layout (regenerate it when they change)."""
    with zipfile.ZipFile(accelnav.example_path("phone_move.zip")) as z:
        shipped = {n: z.read(n).decode() for n in z.namelist()}
    assert shipped == pl.sensor_logger_files(pl.phone())
