"""The task pages' commands run as written: every ``sh`` block that needs no hardware, line by line, in an
empty folder with this Python's ``python`` and ``accelnav`` first on PATH."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

# page -> how many of its sh blocks run here (None: all); the Uno page's last block records from the board
PAGES = {"phone-csv": None, "phone-logger": None, "car-gnss": None, "adxl335-uno": 1}


def _commands(page: str) -> list[str]:
    text = (REPO / "docs" / "tasks" / f"{page}.rst").read_text()
    blocks = re.findall(r"\.\. code-block:: sh\n\n((?:   .*\n|\n)+)", text)[: PAGES[page]]
    return [line[3:] for block in blocks for line in block.splitlines() if line.strip()]


@pytest.mark.parametrize("page", PAGES)
def test_each_command_of_the_page_runs_in_an_empty_folder(page, tmp_path):
    if page == "adxl335-uno" and shutil.which("avr-gcc") is None:
        pytest.skip("codegen --target uno checks the linked size with avr-gcc, which is not installed")
    commands = _commands(page)
    assert len(commands) >= 2, commands
    env = dict(os.environ, MPLBACKEND="Agg", ACCELNAV_CACHE_DIR=str(tmp_path / "cache"))
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    work = tmp_path / "work"
    work.mkdir()
    for cmd in commands:
        done = subprocess.run(["bash", "-c", cmd], cwd=work, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"{cmd}\n{done.stderr[-2000:]}"
    # what each page leaves: a run file, or the Uno's Arduino library
    assert any(work.glob("*.npz")) or any(work.glob("arduino/*/library.properties")), sorted(work.iterdir())
