"""`accelnav --help` imports only what parsing needs; the command table agrees with the modules."""

from __future__ import annotations

import subprocess
import sys

import pytest

from accelnav.cli import ALL, COMMANDS, build_parser, main

HEAVY = ("numpy", "accelnav.estimate", "accelnav.model", "accelnav.native", "accelnav.data", "accelnav.codegen")


@pytest.mark.parametrize("argv", [["--help"], [], ["no-such-command"]], ids=["help", "nothing", "bad-command"])
def test_help_imports_no_estimator(argv):
    code = (
        f"import sys\nfrom accelnav.cli import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
        f"print('imported:', *(m for m in sys.modules if m.startswith({HEAVY!r})))"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    *shown, imported = run.stdout.strip().splitlines()
    assert imported.strip() == "imported:"
    if argv == ["--help"]:
        assert all(any(line.split()[:1] == [name] for line in shown) for name in COMMANDS)
    assert "Traceback" not in run.stderr


def test_table_lines_are_the_modules_own():
    full = {a.dest: a.help for a in build_parser(ALL)._subparsers._group_actions[0]._choices_actions}
    lazy = {a.dest: a.help for a in build_parser(None)._subparsers._group_actions[0]._choices_actions}
    assert list(full) == list(COMMANDS) == list(lazy)  # every command, in the table's order
    assert full == lazy


def test_a_chosen_command_gets_its_full_arguments(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["smooth", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "--zupt" in out and "--covariances" in out and "--compress" in out
