"""Modules imported on first use, so that ``accelnav --help`` and the light commands start fast.

scipy.stats, scipy.optimize and allantools take most of a second to import;
every command module is imported to build the argument parser, but only
``fit-bias``, ``calibrate``, ``tune`` and the simulator use them. A module
that needs one writes ``optimize = lazy_module("scipy.optimize")`` instead of
importing it, and the real import happens at the first attribute read.
"""

from __future__ import annotations

import importlib
import threading
from types import ModuleType


class _LazyModule:
    """Stands in for a module until an attribute is read; then imports it and forwards every read."""

    def __init__(self, name: str):
        self._name = name
        self._module: ModuleType | None = None
        self._lock = threading.Lock()

    def _load(self) -> ModuleType:
        with self._lock:
            if self._module is None:
                self._module = importlib.import_module(self._name)
            return self._module

    def __getattr__(self, attr: str):
        if attr.startswith("__") and attr.endswith("__"):
            raise AttributeError(attr)  # copy/pickle probing: no import for that
        return getattr(self._module or self._load(), attr)

    def __repr__(self) -> str:
        state = "imported" if self._module is not None else "not imported yet"
        return f"<lazy module {self._name!r}, {state}>"


def lazy_module(name: str):
    """A stand-in for the module ``name`` that imports it on the first attribute read."""
    return _LazyModule(name)
