"""The task pages' commands run as written: every ``sh`` block of the pages that need no hardware, line by
line, in an empty folder with this Python's ``python`` and ``accelnav`` first on PATH."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

PAGES = ("phone-csv", "car-gnss")  # the Uno page needs the board; its commands are each command's own tests'


def _commands(page: str) -> list[str]:
    text = (REPO / "docs" / "tasks" / f"{page}.rst").read_text()
    blocks = re.findall(r"\.\. code-block:: sh\n\n((?:   .*\n|\n)+)", text)
    return [line[3:] for block in blocks for line in block.splitlines() if line.strip()]


@pytest.mark.parametrize("page", PAGES)
def test_each_command_of_the_page_runs_in_an_empty_folder(page, tmp_path):
    commands = _commands(page)
    assert len(commands) >= 2, commands
    env = dict(os.environ, MPLBACKEND="Agg", ACCELNAV_CACHE_DIR=str(tmp_path / "cache"))
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    work = tmp_path / "work"
    work.mkdir()
    for cmd in commands:
        done = subprocess.run(["bash", "-c", cmd], cwd=work, env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, f"{cmd}\n{done.stderr[-2000:]}"
    assert any(work.glob("*.npz"))  # each page ends in a run file
