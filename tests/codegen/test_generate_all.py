"""One ``generate`` writes every file the firmware build needs, and every generated file names the one
command that regenerates it (issue 22)."""

from __future__ import annotations

import re

from conftest import MODELS

from accelnav.cli import main
from accelnav.codegen.generated import generate, generated_files
from accelnav.codegen.package import REGENERATE
from accelnav.model.load import load_model

DEFAULT = MODELS / "adxl250_default.toml"
# what firmware.mk compiles and includes from its FW_GEN folder, and the host's decoder reads
FIRMWARE_NEEDS = {"accelnav.h", "accelnav.c", "acnframe.h", "acnframe.c", "acnframe.json"}


def test_accelnav_codegen_writes_what_the_firmware_builds(tmp_path, capsys):
    out = tmp_path / "gen"
    assert main(["codegen", str(DEFAULT), "--out", str(out)]) == 0
    written = {p.name: p.read_text() for p in out.iterdir()}
    assert FIRMWARE_NEEDS <= set(written)
    # the very files the SIL/PIL runners and accelnav.generate build from
    assert written == generated_files(load_model(DEFAULT))


def test_every_generated_file_names_one_regenerate_command():
    files = generate(load_model(DEFAULT))
    commands = {name: re.findall(r"regenerate with `([^`]*)`", text) for name, text in files.items()}
    c_files = [n for n in files if n.endswith((".c", ".h"))]
    assert {n for n in c_files if commands[n] == [REGENERATE]} == set(c_files), commands
    assert REGENERATE.startswith("accelnav codegen ")  # the command above, which writes them all


def test_regenerating_leaves_unchanged_files_alone(tmp_path, capsys):
    """make rebuilds from file times: a second run over the same model touches nothing."""
    out = tmp_path / "gen"
    assert main(["codegen", str(DEFAULT), "--out", str(out)]) == 0
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert main(["codegen", str(DEFAULT), "--out", str(out)]) == 0
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before
