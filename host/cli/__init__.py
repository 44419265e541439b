"""The ``accelnav`` command.

Each subcommand lives in a module that exposes ``register(sub)``: it adds its parser to the argparse
sub-parsers and sets ``func`` to a callable taking the parsed arguments and returning an exit status.
Only the module of the command being run is imported: the others appear in ``accelnav --help`` from
:data:`COMMANDS` (their name and one line), so that the help and a bad command name cost no numpy, no
estimator and no compiler module (tests/cli/test_lazy_parser.py checks the lines against the modules).
Bad input raises :class:`accelnav.errors.UserError` or :class:`accelnav.model.ModelError`; main()
prints those as one line and exits 2. What the library says on its own (``logging`` records under
``accelnav``, and :class:`accelnav.errors.AccelnavWarning` warnings) main() prints for the length of the
command as the lines they always were: a note as it is on stdout, a warning after ``accelnav: `` on
stderr; ``-q`` keeps only the warnings a user must act on (the ``warnings`` ones).

The CLI only parses, runs commands over the library and presents; what computes lives in the library.
Its top-level functions say which by their names (tests/cli/test_cli_names.py holds every module to it;
a leading underscore does not count):

* parsing: ``register``, ``main``, ``build_parser``, ``*_parser``, ``*_args`` / ``*_arg`` (argument groups,
  and readers and checks of the parsed arguments), ``*_options`` (parsed arguments as a library's keywords);
* commands: ``cmd_<command>``, and a part of one named after its command, ``_<command>_*``
  (``_smooth_tune``, ``_hil_recorded``);
* presentation: ``format_*`` / ``fmt_*`` (text), ``print_*`` (lines on stdout), ``write_*`` (the output files
  asked for, and a line saying so), ``*_report``, ``*_table`` / ``table_*``, ``*_summary``, ``report``,
  ``summary``, ``provenance`` (a model file's header).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import sys
import warnings

from accelnav.errors import UserError
from accelnav.progress import set_verbosity

# command -> (module that registers it, its line in `accelnav --help`), in the order the help lists them
COMMANDS: dict[str, tuple[str, str]] = {
    "sim": ("accelnav.cli.core", "simulate a trajectory and the raw sensor output"),
    "filter": ("accelnav.cli.core", "run the forward filter (compiled, float64) over a recording or run file"),
    "smooth": (
        "accelnav.cli.core",
        "filter and RTS-smooth a run file (compiled), optionally with position fixes and zero-velocity updates",
    ),
    "level": (
        "accelnav.cli.level",
        "level a phone or IMU log (body frame, gravity in) into a level-frame recording smooth reads",
    ),
    "init": (
        "accelnav.cli.init",
        "describe a new part (analog, duty-cycle, digital, calibrated) and write its model file",
    ),
    "fit-bias": ("accelnav.cli.fit_bias", "identify the bias model and noise figures from a stationary recording"),
    "calibrate": (
        "accelnav.cli.calibrate",
        "zero-g offset and sensitivity per axis from a recording of still poses (six-position test, or any "
        "orientations of a 3-axis part)",
    ),
    "tune": (
        "accelnav.cli.tune",
        "estimate sigma_n, sigma_eps and R from a motion recording (maximum likelihood of the innovations)",
    ),
    "codegen": ("accelnav.cli.codegen", "generate the per-axis filter in C (fixed point or float32) and its manifest"),
    "record": ("accelnav.cli.record", "record a telemetry link (serial port, pty, socket://, loop://) to a log"),
    "log": ("accelnav.cli.record", "inspect or export a recorded log"),
    "hil": ("accelnav.cli.hil", "run the firmware on simulated data or your recording: SIL (cffi) or PIL (QEMU)"),
    "demo": ("accelnav.cli.demo", "the whole chain on the default model: warm-up, fit, codegen, SIL/PIL, smooth"),
}
ALL = "*"

__all__ = ["ALL", "COMMANDS", "build_parser", "main"]


class _Version(argparse.Action):
    """``--version``: the version read only when asked (argparse's own action takes it as a string when the
    parser is built, and reading it, importlib.metadata, was 30-170 ms of every command, measured)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from accelnav import __version__

        sys.stdout.write(f"accelnav {__version__}\n")  # as argparse's action prints it
        parser.exit()


def build_parser(command: str | None = ALL) -> argparse.ArgumentParser:
    """The parser, with the full arguments of ``command`` (ALL, the default: of every command, as the docs
    need; None: of none, enough for ``accelnav --help``)."""
    parser = argparse.ArgumentParser(
        prog="accelnav",
        description="Short-duration position from a cheap accelerometer: simulate, fit, filter, smooth.",
    )
    parser.add_argument("--version", action=_Version, help="show program's version number and exit")
    talk = parser.add_mutually_exclusive_group()
    talk.add_argument("-v", "--verbose", action="store_true", help="progress bars even when stderr is not a terminal")
    talk.add_argument("-q", "--quiet", action="store_true", help="no notes and no progress, only results and errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    chosen = {module for name, (module, _) in COMMANDS.items() if command in (name, ALL)}
    for module_name in dict.fromkeys(module for module, _ in COMMANDS.values()):
        if module_name in chosen:
            importlib.import_module(module_name).register(sub)
    for name, (_, help_line) in COMMANDS.items():
        if name not in sub.choices:  # a placeholder: parsed again with its module when chosen
            sub.add_parser(name, help=help_line)
    _sort_parser(sub)
    return parser


def _sort_parser(sub) -> None:
    """A module registers all of its commands at once (core: sim, filter, smooth): put the help back in order."""
    order = list(COMMANDS)
    sub._choices_actions.sort(key=lambda a: order.index(a.dest) if a.dest in order else len(order))


def _command_arg(argv: list[str]) -> str | None:
    """The command named in ``argv``: its first word that is not an option (the top-level options, -v, -q,
    --version and --help, take no value, so nothing else can stand before the command)."""
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in COMMANDS else None


class _Lines(logging.Handler):
    """The library's log records as the command's lines: a note (INFO) on stdout as it is, a warning on stderr
    after "accelnav: ". The streams are looked up at each record, so a redirected stdout (an output to '-',
    the demo's captured steps, a test's capture) is followed."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
            if record.levelno >= logging.WARNING:
                print(f"accelnav: {text}", file=sys.stderr)
            else:
                print(text)
        except Exception:
            self.handleError(record)


@contextlib.contextmanager
def print_library_lines(quiet: bool):
    """For one command: the ``accelnav`` logger's notes and warnings as lines (none with ``quiet``: only what
    warnings.warn says then), each once, however deep main() is called (the demo runs commands in itself)."""
    from accelnav.errors import AccelnavWarning

    logger = logging.getLogger("accelnav")
    mine = next((h for h in logger.handlers if isinstance(h, _Lines)), None)
    added = mine is None
    if added:
        mine = _Lines()
        logger.addHandler(mine)
    level = logger.level
    logger.setLevel(logging.ERROR if quiet else logging.INFO)
    shown = warnings.showwarning

    def print_warning(message, category, filename, lineno, file=None, line=None) -> None:
        """A library warning in one line on stderr, as the command's other warnings; others as Python shows them."""
        if issubclass(category, AccelnavWarning):
            print(f"accelnav: warning: {message}", file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = print_warning
    try:
        yield
    finally:
        warnings.showwarning = shown
        logger.setLevel(level)
        if added:
            logger.removeHandler(mine)


def main(argv: list[str] | None = None) -> int:
    if argv is None:  # the command's own process (not a caller's, whose allocator is its own)
        from accelnav.resources import reuse_freed_memory

        reuse_freed_memory()
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_arg(argv))
    args = parser.parse_args(argv)
    set_verbosity(2 if args.verbose else 0 if args.quiet else 1)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from accelnav.cli.args import outputs_args
    from accelnav.fileio import input_limit
    from accelnav.model.load import ModelError
    from accelnav.native.cbuild import BuildError

    with print_library_lines(args.quiet):
        try:
            input_limit()  # a bad ACCELNAV_MAX_INPUT_BYTES is refused before any work, whatever the command
            # every output checked by the one rule before any work; with '-' the data alone goes to stdout
            quiet_stdout = outputs_args(args)
            with contextlib.redirect_stdout(sys.stderr) if quiet_stdout else contextlib.nullcontext():
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
        except OSError as exc:
            from accelnav.fileio import write_failure

            if not write_failure(exc):
                raise
            # a full disk where no writer turned it into its own line (a scratch file, say): still one line
            print(f"accelnav: error: {exc.filename or 'writing'}: {exc.strerror}", file=sys.stderr)
            return 2


if __name__ == "__main__":
    sys.exit(main())
