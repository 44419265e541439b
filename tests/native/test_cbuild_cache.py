"""A compiled module in the cache is code: accelnav.native.cbuild loads only bytes its user's key sealed,
from those very bytes (issue 30). A tiny module keeps each case cheap."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest
from support.cachekey import private_cache, seal_with_other_key
from support.said import listen, one_warning, warned

from accelnav.native import cbuild

CDEF = "int answer(void);"
SRC = {"tiny.c": '#include "tiny.h"\nint answer(void) { return 42; }\n', "tiny.h": "int answer(void);\n"}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    if shutil.which("cc") is None:
        pytest.skip("no C compiler (Debian: gcc)")
    return private_cache(tmp_path, monkeypatch)


def _fresh(stem: str):
    """build_module in a state where this process has not imported the module yet."""
    for name in [n for n in sys.modules if n.startswith(f"_{stem}_")]:
        del sys.modules[name]
    return cbuild.build_module(stem, CDEF, SRC, main="tiny.c")


def _entry(cache):
    (entry,) = (cache / "cffi").glob("_tiny_*.so.sealed")
    return entry


def _hostile_so(tmp_path, marker) -> bytes:
    """A shared object whose constructor writes ``marker`` as soon as it is loaded."""
    src = tmp_path / "own.c"
    src.write_text(
        "#include <stdio.h>\n__attribute__((constructor)) static void own(void) {\n"
        f'    FILE *f = fopen("{marker}", "w"); if (f) {{ fputs("owned", f); fclose(f); }}\n}}\n'
    )
    so = tmp_path / "own.so"
    subprocess.run(["cc", "-shared", "-fPIC", str(src), "-o", str(so)], check=True)
    return so.read_bytes()


def test_a_module_replaced_in_the_cache_is_never_loaded(cache, tmp_path, monkeypatch, capfd, caplog):
    listen(caplog)
    assert _fresh("tiny").lib.answer() == 42
    entry = _entry(cache)
    marker = tmp_path / "MARKER"
    hostile = _hostile_so(tmp_path, marker)
    good = entry.read_bytes()
    for forged in (good[:40] + hostile, None):  # our header with their code; their code sealed their way
        if forged is None:
            seal_with_other_key(entry, hostile, tmp_path, monkeypatch)
        else:
            entry.write_bytes(forged)
        assert _fresh("tiny").lib.answer() == 42
        assert not marker.exists(), "code from the cache ran"
        assert capfd.readouterr().err == ""  # the warning is logged: nothing else on stderr
        line = one_warning(caplog)
        assert f"cache entry {entry}: its seal does not verify" in line and "rebuilt" in line
    assert entry.read_bytes() != hostile


@pytest.mark.parametrize("size", [0, 100, 4096])
def test_a_truncated_module_is_rebuilt_in_one_line(cache, size, capfd, caplog):
    """4096 bytes keep a whole ELF header: loaded from the file, that one was a SIGBUS, not an ImportError."""
    listen(caplog)
    assert _fresh("tiny").lib.answer() == 42
    entry = _entry(cache)
    with open(entry, "r+b") as fh:
        fh.truncate(size)
    assert _fresh("tiny").lib.answer() == 42
    assert capfd.readouterr().err == ""  # the warning is logged: nothing else on stderr
    line = one_warning(caplog)
    assert f"cache entry {entry}:" in line and "rebuilt" in line
    assert _fresh("tiny").lib.answer() == 42 and not warned(caplog)  # rebuilt for good


def test_the_loaded_module_is_not_the_cache_file(cache):
    """Loaded from a sealed memory file: the cache entry can go (or be truncated) under a running module."""
    mod = _fresh("tiny")
    _entry(cache).unlink()
    shutil.rmtree(cache)
    assert mod.lib.answer() == 42
    assert not mod.__file__.startswith(str(cache))
