"""The ``accelnav`` command.

Each subcommand lives in its own module that exposes ``register(sub)``: it
adds its parser to the argparse sub-parsers and sets ``func`` to a callable
taking the parsed arguments and returning an exit status. Bad input raises
:class:`host.errors.UserError` or :class:`codegen.model.ModelError`; main()
prints those as one line and exits 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from codegen.model import ModelError

from .errors import UserError

# Modules that provide subcommands, in the order `accelnav --help` lists them.
COMMAND_MODULES = (
    "host.cmd_core",  # sim, filter, smooth
    "host.cmd_fit_bias",  # fit-bias
    "host.cmd_codegen",  # codegen
    "host.cmd_record",  # record, log info|export
    "host.cmd_hil",  # hil
    "host.cmd_demo",  # demo
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="accelnav",
        description="Short-duration position from a cheap accelerometer: simulate, fit, filter, smooth.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:  # a command not built yet
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (UserError, ModelError) as exc:
        print(f"accelnav: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("accelnav: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
