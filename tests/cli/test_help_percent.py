"""Every --help reads as written: argparse formats help strings with %, but not descriptions (issue 25)."""

from __future__ import annotations

import argparse

import pytest

from accelnav.cli import COMMANDS, build_parser


def _helps(parser: argparse.ArgumentParser):
    """The help text of ``parser`` and of every subcommand below it."""
    yield parser.prog, parser.format_help()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):
                yield from _helps(sub)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_no_help_prints_a_doubled_percent(command):
    texts = dict(_helps(build_parser(command)))
    assert any(prog.endswith(command) for prog in texts)
    bad = {prog: text for prog, text in texts.items() if "%%" in text or "%(" in text}
    assert not bad, bad


def test_calibrate_help_says_95_percent():
    text = dict(_helps(build_parser("calibrate")))["accelnav calibrate"]
    assert "95 % intervals" in " ".join(text.split())
