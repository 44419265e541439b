"""The ``accelnav`` command.

Each subcommand lives in its own module that exposes ``register(sub)``: it
adds its parser to the argparse sub-parsers and sets ``func`` to a callable
taking the parsed arguments and returning an exit status. Bad input raises
:class:`accelnav.errors.UserError` or :class:`codegen.model.ModelError`; main()
prints those as one line and exits 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from accelnav.native.cbuild import BuildError
from accelnav.model.load import ModelError
from accelnav.errors import UserError
from accelnav.progress import set_verbosity

# Modules that provide subcommands, in the order `accelnav --help` lists them.
COMMAND_MODULES = (
    "accelnav.cli.core",  # sim, filter, smooth
    "accelnav.cli.fit_bias",  # fit-bias
    "accelnav.cli.calibrate",  # calibrate
    "accelnav.cli.tune",  # tune
    "accelnav.cli.codegen",  # codegen
    "accelnav.cli.record",  # record, log info|export
    "accelnav.cli.hil",  # hil
    "accelnav.cli.demo",  # demo
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="accelnav",
        description="Short-duration position from a cheap accelerometer: simulate, fit, filter, smooth.",
    )
    from accelnav import __version__

    parser.add_argument("--version", action="version", version=f"accelnav {__version__}")
    talk = parser.add_mutually_exclusive_group()
    talk.add_argument("-v", "--verbose", action="store_true", help="progress bars even when stderr is not a terminal")
    talk.add_argument("-q", "--quiet", action="store_true", help="no notes and no progress, only results and errors")
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
    set_verbosity(2 if args.verbose else 0 if args.quiet else 1)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (UserError, ModelError) as exc:
        print(f"accelnav: error: {exc}", file=sys.stderr)
        return 2
    except BuildError as exc:  # no C compiler for a run-time build (SIL), or the C did not compile
        print(f"accelnav: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("accelnav: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (accelnav ... | head): not an error of ours
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
