"""The C kernels compiled into the package (setup.py's cffi_modules) and their run-time fallbacks.

Each kernel (the smoother's, codegen's Riccati recursion and schedule search, the telemetry decoder's
frame kernel) is used prebuilt only when the sha256 it carries equals the C beside it; otherwise it is
built through the cffi builder. Both builds of the Riccati kernel must give the very doubles of the
Python twin. The wheel side (no compiler reachable) is in tests/package/test_package.py.
"""

from __future__ import annotations

import re
import shutil
import zlib

import numpy as np
import pytest
from conftest import MODELS

from accelnav.codegen import gains
from accelnav.codegen.bounds import error_bound
from accelnav.codegen.ranges import plan_axis
from accelnav.data import csvnum
from accelnav.estimate import fastsmooth
from accelnav.link import wirekernel
from accelnav.model.load import load_model
from accelnav.native.cbuild import STRICT_FLAGS
from accelnav.native.kernels import RICCATI_FLAGS as WHEEL_FLAGS

# (module holding CSRC and the prebuilt check, the check, the kernel's C file)
KERNELS = {
    "riccati": (gains, "_riccati_prebuilt", "riccati.c"),
    "wire": (wirekernel, "_prebuilt", "acnwire.c"),
    "csvnum": (csvnum, "_prebuilt", "csvnum.c"),
    "fastsmooth": (fastsmooth, "_prebuilt", "fastsmooth.c"),
}
REINSTALL = "the package's build of this kernel is missing or stale: reinstall (pip install -e . / make setup)"


@pytest.mark.parametrize("name", sorted(KERNELS))
def test_a_prebuilt_kernel_is_used_only_with_the_c_it_was_built_from(name, tmp_path, monkeypatch):
    """The package's module is served for the C beside it, and not once that C differs by one comment."""
    owner, check, cfile = KERNELS[name]
    assert getattr(owner, check)() is not None, REINSTALL
    csrc = tmp_path / "csrc"
    shutil.copytree(owner.CSRC, csrc)
    monkeypatch.setattr(owner, "CSRC", csrc)
    assert getattr(owner, check)() is not None, "an identical copy of the C must match"
    with open(csrc / cfile, "a") as f:
        f.write("/* edited */\n")
    assert getattr(owner, check)() is None, "a prebuilt module built from other C was served"


def test_the_crc_table_in_the_c_reproduces_zlib():
    """The wire kernel's CRC-32 table is a literal in acnwire.c: read from there, it must give zlib's CRC
    (checked without a compiler, so a wrong word cannot hide behind the numpy path)."""
    text = (wirekernel.CSRC / "acnwire.c").read_text()
    body = re.search(r"acnw_table\[256\]\s*=\s*\{(.*?)\};", text, re.S)
    assert body, "acnw_table not found in acnwire.c"
    table = [int(w, 16) for w in re.findall(r"0x([0-9a-fA-F]{8})u", body.group(1))]
    assert len(table) == 256
    rng = np.random.default_rng(1)
    for size in (0, 1, 7, 177, 4096):
        data = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        crc = 0xFFFFFFFF
        for b in data:
            crc = table[(crc ^ b) & 0xFF] ^ (crc >> 8)
        assert crc ^ 0xFFFFFFFF == zlib.crc32(data), size


def test_the_wheel_build_keeps_the_flags_that_decide_the_doubles():
    """kernel_build.RICCATI_FLAGS (the wheel) are among the run-time build's flags, and name no contraction and
    no fast math: both builds compute the same doubles."""
    assert {"-ffp-contract=off", "-fno-fast-math", "-std=c99"} <= set(WHEEL_FLAGS)
    assert set(WHEEL_FLAGS) <= set(gains._BUILD_FLAGS)
    assert set(STRICT_FLAGS) <= set(gains._BUILD_FLAGS)


@pytest.fixture(params=["prebuilt", "builder"])
def riccati_kernel(request, monkeypatch):
    """gains' C kernel forced to one build: the package's own, or the cffi builder's from the same C."""
    mod = gains._riccati_prebuilt() if request.param == "prebuilt" else gains._riccati_built()
    assert mod is not None, REINSTALL if request.param == "prebuilt" else "a C compiler is on this machine"
    monkeypatch.setattr(gains, "_riccati_lib", lambda: (mod.ffi, mod.lib))
    gains._SCHEDULES.clear()
    yield mod
    gains._SCHEDULES.clear()


def test_each_build_of_the_riccati_kernel_gives_the_python_doubles(riccati_kernel, monkeypatch):
    """The recursion, the schedule's search and account, and the error bound's recursion: through this
    build and through the Python twins, the same numbers bit for bit."""
    model = load_model(MODELS / "adxl250_default.toml")
    p = plan_axis(model, 1, "gain_schedule")
    key = gains._key(p.design)
    n = 30_000
    valid = np.ones(n, dtype=bool)
    valid[1500:1530] = False
    fast, slow = gains._riccati(key, n, valid, 1000, (1500, 2222)), gains._riccati_py(key, n, valid, 1000, (1500, 2222))
    for name in ("K", "sigma", "S", "row_K", "row_sigma", "row_S", "kmax", "sigma_max", "max_prior", "max_c"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
    assert fast.checkpoints == slow.checkpoints and (fast.S_min, fast.S_max) == (slow.S_min, slow.S_max)

    fm = tuple(p.vars["K" + v].fmt for v in "rvae")
    out = []
    for lib in ((riccati_kernel.ffi, riccati_kernel.lib), None):
        monkeypatch.setattr(gains, "_riccati_lib", lambda lib=lib: lib)
        gains._SCHEDULES.clear()
        s = gains.schedule_of(p.design, n, fm, 1e-4, ramp=1000, floor=2.0)
        out.append((s, error_bound(p, n, s, valid=valid)))
    (c_s, c_b), (py_s, py_b) = out
    assert len(c_s.lengths) > 3, "a schedule of a few segments at least: something to compare"
    assert (c_s.lengths, c_s.slopes, c_s.start) == (py_s.lengths, py_s.slopes, py_s.start)
    assert np.array_equal(c_s.max_error, py_s.max_error)
    assert np.array_equal(c_b, py_b)
