"""The firmware's libFuzzer tools (firmware/fuzz/fuzz.py: clang, the sanitizers, libFuzzer's figures) for
the tests that build a harness, and the one rule for when they are missing."""

from __future__ import annotations

import importlib.util
import os

import pytest

from accelnav.resources import firmware_dir


def fuzz_module():
    """firmware/fuzz/fuzz.py as a module (skips where an installed wheel carries no fuzz harness)."""
    path = firmware_dir() / "fuzz" / "fuzz.py"
    if not path.is_file():
        pytest.skip(f"{path} absent (an installed wheel carries no fuzz harness)")
    spec = importlib.util.spec_from_file_location("accelnav_fuzz_rx", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def unavailable(reason: str):
    """Skip, saying why; a failure under ACCELNAV_REQUIRE_FUZZ=1 (CI installs clang and its fuzzer runtime)."""
    if os.environ.get("ACCELNAV_REQUIRE_FUZZ") == "1":
        pytest.fail(f"ACCELNAV_REQUIRE_FUZZ=1 but {reason}")
    pytest.skip(reason)
