"""Running the command in-process, as the CLI tests do."""

from __future__ import annotations

from accelnav.cli import main


def run_cli(argv, capsys) -> tuple[int, str, str]:
    """``accelnav ARGV`` through main(): (exit status, stdout, stderr), arguments as strings (paths welcome)."""
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err
