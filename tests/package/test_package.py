"""The wheel, as a user gets it: one top-level name, its data inside, every command from an empty folder.

The wheel is built from this checkout and unpacked into a folder that alone
is put on PYTHONPATH; the commands run from another, empty folder, with the
cache in a third. That is what ``pip install`` of the wheel gives, minus the
dependency resolution (CI also does the real install into a fresh venv and
runs ``accelnav demo``, see .ci/run).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

DATA = (
    "accelnav/py.typed",  # the public API is typed (PEP 561)
    "accelnav/models/adxl250_default.toml",
    "accelnav/models/adxl202_duty.toml",
    "accelnav/models/examples/phone_move.zip",  # the README's phone block reads it (accelnav.example_path)
    "accelnav/firmware/firmware.mk",
    "accelnav/firmware/parts.mk",  # the part table firmware.mk and the codegen report share
    "accelnav/firmware/src/app.c",
    "accelnav/firmware/boards/acn_board.h",
    "accelnav/firmware/boards/host/board_host.c",
    "accelnav/firmware/boards/emu_feed.c",
    "accelnav/firmware/boards/arduino/AccelNav.cpp",  # the Arduino library's class, and its licence text
    "accelnav/firmware/boards/arduino/LICENSE",  # PIL's file feed: `accelnav demo --pil on` from the wheel builds it
    "accelnav/firmware/boards/mps2_an385/mps2_an385.ld",
    "accelnav/firmware/boards/stm32f103/stm32f103c8.ld",
    "accelnav/estimate/csrc/fastsmooth.c",
    "accelnav/estimate/csrc/fastsmooth.h",
    "accelnav/codegen/csrc/riccati.c",
    "accelnav/codegen/csrc/riccati.h",
    "accelnav/codegen/csrc/acn_runtime.h",  # the fixed-point runtime the generator copies into every filter
    "accelnav/link/csrc/acnwire.c",
    "accelnav/link/csrc/acnwire.h",
    "accelnav/data/csrc/csvnum.c",
    "accelnav/data/csrc/csvnum.h",
)
# the C kernels compiled into the wheel (setup.py's cffi_modules): used with no C compiler on the machine
KERNELS = ("accelnav.estimate._fastsmooth", "accelnav.codegen._riccati", "accelnav.link._acnwire",
           "accelnav.data._csvnum")  # fmt: skip


def test_wheel_has_one_top_level_name_and_its_data(wheel):
    _, names, _ = wheel
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"accelnav"}
    missing = [d for d in DATA if d not in names]
    assert not missing, missing
    for mod in KERNELS:
        stem = mod.replace(".", "/")
        assert any(n.startswith(stem + ".") and n.endswith(".so") for n in names), f"{mod} is not in the wheel"


def _run(site: Path, cwd: Path, cache: Path, *args: str, env_extra: dict | None = None, timeout: int = 300):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ACCELNAV_CACHE_DIR")}
    env.update(PYTHONPATH=str(site), ACCELNAV_CACHE_DIR=str(cache), MPLBACKEND="Agg", **(env_extra or {}))
    done = subprocess.run(
        [sys.executable, "-m", "accelnav", *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )
    assert done.returncode == 0, f"accelnav {' '.join(args)}:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    return done.stdout


def _tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if "__pycache__" not in p.parts}


def test_commands_work_from_an_empty_folder(wheel, tmp_path):
    _, _, site = wheel
    work, cache = tmp_path / "work", tmp_path / "cache"
    work.mkdir()
    before = _tree(site)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(site)
    where = subprocess.run(
        [sys.executable, "-c", "import accelnav; print(accelnav.__file__)"],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
    )
    assert Path(where.stdout.strip()).is_relative_to(site), where

    _run(site, work, cache, "sim", "--scenario", "stop_and_go", "--duration", "20", "--out", "run.npz")
    _run(site, work, cache, "filter", "run.npz", "--out", "filtered.npz")
    # the smoother's kernel comes with the wheel: no C compiler is reached for (CC would fail)
    out = _run(
        site, work, cache, "smooth", "run.npz", "--zupt", "auto", "--out", "smoothed.npz", env_extra={"CC": "false"}
    )
    assert "smoother" in out.lower()
    _run(site, work, cache, "sim", "--scenario", "stationary", "--duration", "300", "--seed", "4", "--out", "st.npz")
    _run(site, work, cache, "fit-bias", "st.npz", "--out", "fitted.toml")
    # the same for codegen's Riccati kernel (in Python its codegen takes 30x longer), the decoder's frame kernel
    # and the CSV reader's number parser
    code = (
        "from accelnav.codegen import gains; from accelnav.link import wirekernel; "
        "from accelnav.estimate import fastsmooth; from accelnav.data import csvnum; "
        "used = fastsmooth._lib(), gains._riccati_module(), wirekernel.wire_lib(), csvnum.csv_lib(); "
        "print(*(getattr(m, '__name__', m) for m in used))"
    )
    used = subprocess.run(
        [sys.executable, "-c", code],
        cwd=work,
        env={**env, "CC": "false", "ACCELNAV_CACHE_DIR": str(cache)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert used.returncode == 0, used.stderr[-3000:]
    assert used.stdout.split() == list(KERNELS), f"kernels used with no compiler: {used.stdout}"
    _run(site, work, cache, "codegen", "fitted.toml", "--out", "gen", env_extra={"CC": "false"})
    assert {"accelnav.c", "accelnav.h", "accelnav.json"} <= {p.name for p in (work / "gen").iterdir()}
    out = _run(site, work, cache, "hil", "--target", "sil", "--scenario", "stop_and_go", "--duration", "10")
    assert "firmware vs float64 reference" in out
    for f in ("run.npz", "filtered.npz", "smoothed.npz", "fitted.toml"):
        assert (work / f).is_file(), f
    assert _tree(site) == before, "a run wrote into the installed package"
    assert any(cache.rglob("*.so.sealed")), "SIL builds were expected in the cache folder"


def test_a_run_time_build_without_a_compiler_is_refused_in_one_line(tmp_path):
    """SIL compiles the user's generated C: with no compiler that is one line naming Debian's package."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(CC=str(tmp_path / "no-such-cc"), ACCELNAV_CACHE_DIR=str(tmp_path / "cache"))
    # a 60 s declared run: quick even where the generator's Riccati kernel is not prebuilt and runs in Python
    from accelnav.resources import models_dir

    text = (models_dir() / "adxl250_default.toml").read_text()
    short, n = re.subn(r"^max_run_s = .*$", "max_run_s = 60.0", text, flags=re.M)
    assert n == 1
    (tmp_path / "short.toml").write_text(short)
    done = subprocess.run(
        [sys.executable, "-m", "accelnav", "hil", "--target", "sil", "--duration", "2", "--model", "short.toml"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert "not found" in line and "Debian: gcc" in line


def test_the_parser_is_built_without_the_heavy_imports():
    """Every command module is imported to build the parser (``accelnav --help``, any command); scipy's stats
    and optimize, allantools and matplotlib are imported by the commands that use them, at first use
    (accelnav.lazy), not at start: they cost most of a second."""
    code = (
        "import sys; from accelnav.cli import build_parser; build_parser(); "
        "print(' '.join(m for m in ('scipy.stats', 'scipy.optimize', 'scipy.signal', 'allantools', 'matplotlib')"
        " if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == ""


def test_a_lazy_module_imports_on_first_use():
    from accelnav.lazy import lazy_module

    stats = lazy_module("scipy.stats")
    assert "not imported yet" in repr(stats) or "scipy.stats" in sys.modules
    assert float(stats.norm.cdf(0.0)) == 0.5
    assert "imported" in repr(stats) and "not" not in repr(stats)
    with pytest.raises(ModuleNotFoundError):
        getattr(lazy_module("no_such_module_here"), "anything")  # noqa: B009


def _newer_python(version: str) -> str | None:
    """An interpreter of ``version`` (3.12, 3.13) on PATH or under pyenv, as this machine image and CI's have."""
    pyenv = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv")) / "versions"
    candidates = [str(f / "bin" / "python") for f in sorted(pyenv.glob(f"{version}.*"), reverse=True)]
    candidates += [p for p in [shutil.which(f"python{version}")] if p]
    for python in candidates:  # a pyenv shim on PATH may name a version it cannot run: ask it
        probe = subprocess.run(
            [python, "-c", "import sys; print(sys.version_info[:2])"], capture_output=True, text=True
        )
        if probe.returncode == 0 and probe.stdout.strip() == str(tuple(int(x) for x in version.split("."))):
            return python
    return None


@pytest.mark.parametrize("version", ["3.12", "3.13"])
def test_the_wheel_installs_and_runs_on_newer_pythons(version, wheel, tmp_path):
    """One abi3 wheel for 3.11 and later, installed by pip into a venv without setuptools (3.12 dropped it):
    the demo's SIL run compiles the generated C at run time, which cffi's own compile path would refuse there."""
    python = _newer_python(version)
    if python is None:
        if os.environ.get("ACCELNAV_REQUIRE_PYTHONS") == "1":
            pytest.fail(f"Python {version} not found (ACCELNAV_REQUIRE_PYTHONS=1)")
        pytest.skip(f"Python {version} not found on PATH or under pyenv")
    whl, _, _ = wheel
    assert "-abi3-" in whl.name, f"{whl.name}: pip on {version} would call it 'not a supported wheel'"
    venv = tmp_path / "venv"
    subprocess.run([python, "-m", "venv", str(venv)], check=True, timeout=120)
    pip = subprocess.run(
        [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", str(whl)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    if pip.returncode != 0 and "Could not find a version" in pip.stderr:
        pytest.skip(f"dependencies of the wheel not reachable for Python {version}: {pip.stderr.strip()[-200:]}")
    assert pip.returncode == 0, pip.stderr[-3000:]
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "uninstall", "-q", "-y", "setuptools"], timeout=120)
    probe = subprocess.run([str(venv / "bin" / "python"), "-c", "import setuptools"], capture_output=True)
    assert probe.returncode != 0, "setuptools is in the venv: the test would not show the run needs none"
    work = tmp_path / "empty"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ACCELNAV_CACHE_DIR")}
    env.update(ACCELNAV_CACHE_DIR=str(tmp_path / "cache"), MPLBACKEND="Agg")
    done = subprocess.run(
        [str(venv / "bin" / "accelnav"), "demo", "--pil", "off", "--out", "d"],
        cwd=work, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert (work / "d" / "report.md").is_file()
