"""The strict compiler flags have one definition: FW_WARN in firmware/parts.mk, which the firmware's make
files include and accelnav.native.cbuild reads for every Python caller (issue 22)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

import accelnav
import accelnav.codegen
import accelnav.hil_sim
from accelnav.native.cbuild import STRICT_FLAGS, STRICT_WARN
from accelnav.resources import firmware_dir

# the wheel's build of the Riccati kernel: warnings only, no -Werror (host/native/kernels.py says why)
NOT_STRICT = {"kernels.py"}


def test_python_reads_the_flags_make_uses():
    """make itself expands FW_WARN: what the Python side parsed is what the firmware build gets."""
    if shutil.which("make") is None:
        pytest.skip("make not found (Debian: make)")
    script = f"include {firmware_dir() / 'parts.mk'}\nall:\n\t@echo $(FW_WARN)\n"
    done = subprocess.run(["make", "-s", "-f", "-"], input=script, capture_output=True, text=True, check=True)
    assert tuple(done.stdout.split()) == STRICT_WARN
    assert {"-Werror", "-Wall", "-Wextra"} <= set(STRICT_WARN)
    assert STRICT_FLAGS[: len(STRICT_WARN)] == STRICT_WARN


def test_no_python_module_spells_the_flags_again():
    """Every Python build (the generator's report, the SIL harness, the firmware, simavr, the fuzz harness)
    takes the flags from accelnav.native.cbuild instead of its own list."""
    roots = [Path(accelnav.__file__).parent, Path(accelnav.codegen.__file__).parent]
    roots += [Path(accelnav.hil_sim.__file__).parent, firmware_dir()]
    spelled = sorted(
        str(path)
        for root in roots
        for path in root.rglob("*.py")
        if path.name not in NOT_STRICT and '"-Wextra"' in path.read_text()
    )
    assert not spelled, f"strict flags spelled outside firmware/parts.mk: {spelled}"


@pytest.mark.parametrize(
    "module", ["accelnav.estimate.fastsmooth", "accelnav.link.wirekernel", "accelnav.codegen.gains"]
)
def test_each_host_kernel_compiles_with_the_strict_flags(module, tmp_path):
    """A kernel whose prebuilt module is stale (an edited checkout, another compiler) is compiled at run time
    with STRICT_FLAGS: its C must pass them, -pedantic included (a merge once put C99-invalid const
    array parameters into the smoother, which only the run-time build refused)."""
    import importlib

    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler (Debian: gcc)")
    csrc = importlib.import_module(module).CSRC
    for c in sorted(csrc.glob("*.c")):
        done = subprocess.run(
            [cc, *STRICT_FLAGS, "-fsyntax-only", f"-I{csrc}", str(c)], capture_output=True, text=True, cwd=tmp_path
        )
        assert done.returncode == 0, f"{c.name}:\n{done.stderr}"
