"""The CLI is argument parsing, command functions and presentation only: every top-level function of every
module of accelnav.cli is named as one of those (the rule is in accelnav/cli/__init__.py's docstring), so
library logic that creeps into the CLI shows up here by its name."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import accelnav.cli
from accelnav.cli import COMMANDS

CLI = Path(accelnav.cli.__file__).parent
PARSING = ("register", "main", "build_parser")
PARSING_ENDS = ("_parser", "_args", "_arg", "_options")
COMMAND_PARTS = tuple(f"_{name.replace('-', '_')}_" for name in COMMANDS)
SHOWING_STARTS = ("format_", "fmt_", "print_", "write_", "table_")
SHOWING_ENDS = ("_report", "_table", "_summary")
SHOWING = ("report", "summary", "provenance")


def role(name: str) -> str | None:
    """'parsing', 'command' or 'presentation' by the naming rule; None for a name that is none of them."""
    bare = name.lstrip("_")
    if bare in PARSING or bare.endswith(PARSING_ENDS):
        return "parsing"
    if bare.startswith("cmd_") or name.startswith(COMMAND_PARTS):
        return "command"
    if bare in SHOWING or bare.startswith(SHOWING_STARTS) or bare.endswith(SHOWING_ENDS):
        return "presentation"
    return None


def _functions(path: Path) -> list[tuple[str, int]]:
    tree = ast.parse(path.read_text(), filename=str(path))
    return [(n.name, n.lineno) for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


MODULES = sorted(CLI.glob("*.py"))


def test_the_cli_has_its_modules():
    assert {"__init__.py", "core.py", "args.py"} <= {p.name for p in MODULES}


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.stem)
def test_every_function_parses_runs_a_command_or_presents(path):
    loose = [f"{path.name}:{line}: {name}" for name, line in _functions(path) if role(name) is None]
    assert not loose, (
        "functions that are neither parsing, a command nor presentation (move the work into the library, or "
        "name them by the rule in accelnav/cli/__init__.py):\n" + "\n".join(loose)
    )


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("register", "parsing"),
        ("read_args", "parsing"),
        ("reader_options", "parsing"),
        ("cmd_smooth", "command"),
        ("_smooth_bounded", "command"),
        ("_fit_bias_plots", "command"),
        ("format_counts", "presentation"),
        ("_summary", "presentation"),
        ("provenance", "presentation"),
        ("require_scenario", None),
        ("_consistency", None),
        ("run", None),
        ("_smoothing", None),
    ],
)
def test_the_rule_tells_the_roles_apart(name, expected):
    assert role(name) == expected
