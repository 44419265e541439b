"""The package's shape: one import name, layers that only import downward, no import circle.

Read from the source with ast (every import statement, also those inside
functions), so a lazy import cannot hide an upward arrow.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO, TESTS

import accelnav

ROOT = Path(accelnav.__file__).parent  # host/ in a checkout, accelnav/ in a wheel

# rank of each part of the package: an import may only go to the same rank or a lower one
LAYERS: dict[str, float] = {
    "accelnav.cli": 7,
    "accelnav.__main__": 7,
    "accelnav.api": 6,  # the library's face: calls into every stage below, imported only by accelnav/__init__
    "accelnav.plots": 6,
    "accelnav.identify": 5,
    "accelnav.hil_sim.targets": 5,
    "accelnav.data": 4,
    "accelnav.level": 3,  # body-frame IMU records -> level frame; stands on estimate (rests)
    "accelnav.link": 3,
    # inside the link: the decoder stands on the codec and the loss accounting, both on the manifest
    "accelnav.link.decoder": 3,
    "accelnav.link.codec": 2.8,
    "accelnav.link.accounting": 2.8,
    "accelnav.link.manifest": 2.6,
    "accelnav.codegen": 2,
    "accelnav.estimate": 2,
    "accelnav.hil_sim.sim": 2,
    "accelnav.hil_sim": 2,
    "accelnav.model": 1,
    "accelnav.native": 1,
    "accelnav.resources": 0,
    "accelnav.errors": 0,
    "accelnav.fileio": 0,
    "accelnav.cachefile": 0,
    "accelnav.progress": 0,
    "accelnav.lazy": 0,
}

# the float64 oracle and everything a user's data passes through never stand on the generator
NEVER_CODEGEN = ("accelnav.model", "accelnav.native", "accelnav.estimate", "accelnav.identify", "accelnav.data",
                 "accelnav.level",
                 "accelnav.hil_sim.sim", "accelnav.plots")  # fmt: skip
# what the generator may stand on
CODEGEN_BASE = ("accelnav.codegen", "accelnav.model", "accelnav.native", "accelnav.resources", "accelnav.fileio",
                "accelnav.cachefile")  # fmt: skip


def _modules() -> dict[str, Path]:
    """Every module of the installed package by dotted name (subpackages may live in other folders)."""
    import accelnav.codegen
    import accelnav.hil_sim

    roots = {
        "accelnav": ROOT,
        "accelnav.codegen": Path(accelnav.codegen.__file__).parent,
        "accelnav.hil_sim": Path(accelnav.hil_sim.__file__).parent,
    }
    out = {}
    for prefix, root in roots.items():
        for path in root.rglob("*.py"):
            rel = path.relative_to(root).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            name = ".".join([prefix, *parts])
            if name.startswith("accelnav.codegen") and prefix == "accelnav" or "csrc" in parts:
                continue
            out.setdefault(name, path)
    return out


def _imports(name: str, path: Path) -> list[tuple[str, int, bool]]:
    """(imported module, line, at module level) for each accelnav import in one file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    top_level = {id(n) for n in tree.body}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [mod] if node.module else [f"{mod}.{a.name}" for a in node.names]
        else:
            continue
        for t in targets:
            if t == "accelnav" or t.startswith("accelnav."):
                found.append((t, node.lineno, id(node) in top_level))
    return found


def _rank(module: str) -> int | None:
    for prefix, rank in sorted(LAYERS.items(), key=lambda kv: -len(kv[0])):
        if module == prefix or module.startswith(prefix + "."):
            return rank
    return None


MODULES = _modules()


def test_every_module_has_a_layer():
    loose = [m for m in MODULES if m != "accelnav" and _rank(m) is None]
    assert not loose, f"modules outside every layer (add them to LAYERS): {loose}"


def test_no_import_runs_upward():
    bad = []
    for name, path in MODULES.items():
        mine = _rank(name)
        for target, line, _ in _imports(name, path):
            theirs = _rank(target)
            if mine is not None and theirs is not None and theirs > mine:
                bad.append(f"{path}:{line}: {name} (layer {mine}) imports {target} (layer {theirs})")
    assert not bad, "\n".join(bad)


def _under(module: str, prefixes) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def test_codegen_stands_on_model_and_native_only():
    bad = [
        f"{path}:{line}: {target}"
        for name, path in MODULES.items()
        if _under(name, ("accelnav.codegen",))
        for target, line, _ in _imports(name, path)
        if not _under(target, CODEGEN_BASE)
    ]
    assert not bad, "\n".join(bad)


def test_oracle_side_never_imports_codegen():
    bad = [
        f"{path}:{line}: {name} imports {target}"
        for name, path in MODULES.items()
        if _under(name, NEVER_CODEGEN)
        for target, line, _ in _imports(name, path)
        if _under(target, ("accelnav.codegen",))
    ]
    assert not bad, "\n".join(bad)


def test_nothing_imports_the_cli():
    bad = [
        f"{path}:{line}: {name} imports {target}"
        for name, path in MODULES.items()
        if not _under(name, ("accelnav.cli", "accelnav.__main__"))
        for target, line, _ in _imports(name, path)
        if _under(target, ("accelnav.cli",))
    ]
    assert not bad, "\n".join(bad)


def _resolve(target: str) -> str | None:
    """The module an import names (``from pkg import mod`` names mod when mod is a module)."""
    while target and target not in MODULES:
        target = target.rpartition(".")[0]
    return target or None


@pytest.mark.parametrize("lazy", [False, True], ids=["module-level", "all imports"])
def test_no_import_circle(lazy):
    graph = {
        name: {
            r
            for t, _, top in _imports(name, path)
            if (top or lazy) and (r := _resolve(t)) and r != name and not name.startswith(r + ".")
        }
        for name, path in MODULES.items()
    }
    # a package's __init__ importing its own children is not a circle; drop those edges
    seen, stack, cycle = set(), [], []

    def visit(n):
        if n in stack:
            cycle.extend(stack[stack.index(n) :] + [n])
            return True
        if n in seen:
            return False
        seen.add(n)
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if visit(m):
                return True
        stack.pop()
        return False

    for n in sorted(graph):
        if visit(n):
            break
    assert not cycle, " -> ".join(cycle)


def test_one_import_name(tmp_path):
    """From an empty folder (so the checkout is not on sys.path), only ``accelnav`` imports."""
    code = (
        "import importlib.util, accelnav, accelnav.codegen, accelnav.hil_sim, accelnav.cli\n"
        "print([n for n in ('host', 'codegen', 'hil_sim') if importlib.util.find_spec(n)])"
    )
    done = subprocess.run([sys.executable, "-I", "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def _imported_test_modules(path: Path) -> list[tuple[str, int]]:
    """(module, line) for each import of a test_* module in one file, lazy ones and importlib's included."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module]
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
        ):
            names = [str(node.args[0].value)]
        else:
            continue
        found += [(n, node.lineno) for n in names if any(part.startswith("test_") for part in n.split("."))]
    return found


def test_no_test_imports_another_test():
    """Shared code lives in tests/support (or conftest), never in a test module another file imports: a test
    file is collected, not imported, and its helpers would run under two names. The bench scripts too."""
    files = sorted(TESTS.rglob("*.py")) + sorted((REPO / "bench").rglob("*.py"))
    bad = [f"{f.relative_to(REPO)}:{line} imports {mod}" for f in files for mod, line in _imported_test_modules(f)]
    assert not bad, "\n".join(bad)


def test_test_files_mirror_the_packages():
    """Test files sit in a folder per package (none loose in tests/), with names unique across tests/ and no
    __init__.py: pytest imports them by basename, and two test_x.py would collide."""
    files = sorted(p for p in TESTS.rglob("test_*.py"))
    loose = [p.name for p in files if p.parent == TESTS]
    assert not loose, f"move these into the folder of the package they test: {loose}"
    seen: dict[str, Path] = {}
    twins = [
        f"{p.relative_to(TESTS)} and {seen[p.name].relative_to(TESTS)}"
        for p in files
        if seen.setdefault(p.name, p) != p
    ]
    assert not twins, f"test files with one name: {twins}"
    inits = [str(p.relative_to(TESTS)) for p in TESTS.rglob("__init__.py")]
    assert not inits, f"no __init__.py under tests/: {inits}"


# library work that `accelnav filter` and `smooth` leave to the engine (accelnav.estimate.engine, reached through
# accelnav.data.smoothing): choosing how a run is read and cut, building the aids, deciding the rests, tuning
ENGINE_WORK = {"smooth_bounded", "array_reader", "NpzReader", "whole_bytes", "chunk_samples", "disk_needed",
               "open_stream", "estimate_rows", "read_input", "Aids", "axis_aids", "candidates", "gate_rests",
               "rest_mask", "read_fixes", "read_zupt_file", "smooth_run", "filter_run", "tune_run",
               "smooth_arrays", "filter_arrays"}  # fmt: skip


def _names_reached(tree: ast.Module, start: str) -> set[str]:
    """Every name and attribute used by function ``start`` of a module and the module's functions it calls."""
    funcs = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    seen, todo, used = set(), [start], set()
    while todo:
        f = todo.pop()
        if f in seen or f not in funcs:
            continue
        seen.add(f)
        for node in ast.walk(funcs[f]):
            if isinstance(node, ast.Name):
                used.add(node.id)
                todo.append(node.id)
            elif isinstance(node, ast.Attribute):
                used.add(node.attr)
    return used


@pytest.mark.parametrize("command", ["cmd_smooth", "cmd_filter"])
def test_filter_and_smooth_commands_parse_and_print_only(command):
    """No path choice, no aid building in the CLI: what the command reaches of the library is the engine's face."""
    tree = ast.parse((ROOT / "cli" / "core.py").read_text())
    assert command in {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    reached = _names_reached(tree, command)
    assert "smooth_file" in reached  # the check can see a call (fails if the walk finds nothing)
    assert not reached & ENGINE_WORK, f"{command} does the engine's work: {sorted(reached & ENGINE_WORK)}"
