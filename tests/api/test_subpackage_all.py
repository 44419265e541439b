"""Every sub-package of accelnav says what its users import (``__all__``), and every name it lists is there."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

import accelnav
import accelnav.codegen
import accelnav.firmware
import accelnav.hil_sim
import accelnav.models

# packages that carry only data (model files, firmware sources): an empty __all__, said so
DATA_ONLY = {"accelnav.models", "accelnav.firmware"}


def _packages() -> list[str]:
    """Dotted names of every sub-package of the installed accelnav (codegen and hil_sim live in their own folders)."""
    roots = {
        "accelnav": Path(accelnav.__file__).parent,
        "accelnav.codegen": Path(accelnav.codegen.__file__).parent,
        "accelnav.hil_sim": Path(accelnav.hil_sim.__file__).parent,
        # their own folders in a checkout, beside the others in an installed wheel: found either way
        "accelnav.models": Path(accelnav.models.__file__).parent,
        "accelnav.firmware": Path(accelnav.firmware.__file__).parent,
    }
    out = set()
    for prefix, root in roots.items():
        for init in root.rglob("__init__.py"):
            parts = init.parent.relative_to(root).parts
            if "csrc" in parts or "__pycache__" in parts or (parts and ".".join([prefix, *parts]) in DATA_ONLY):
                continue
            out.add(".".join([prefix, *parts]))
    out.discard("accelnav")  # the library's face: its own test (tests/api)
    return sorted(out)


PACKAGES = _packages()


def test_the_subpackages_are_found():
    assert {"accelnav.link", "accelnav.estimate", "accelnav.codegen", "accelnav.hil_sim.sim"} <= set(PACKAGES)


@pytest.mark.parametrize("name", PACKAGES)
def test_all_is_declared_and_every_name_resolves(name):
    pkg = importlib.import_module(name)
    names = getattr(pkg, "__all__", None)
    if name in DATA_ONLY:
        assert names == [], f"{name}: a data-only package declares an empty __all__"
        return
    assert isinstance(names, list) and names, f"{name}: no __all__"
    assert len(set(names)) == len(names), f"{name}: __all__ lists a name twice"
    missing = []
    for n in names:
        if hasattr(pkg, n):
            continue
        try:
            importlib.import_module(f"{name}.{n}")  # a module of the package, listed by its name
        except ModuleNotFoundError:
            missing.append(n)
    assert not missing, f"{name}.__all__ names what is not there: {missing}"
