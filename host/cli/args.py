"""Argument groups more than one command takes, defined once so that their names and help agree."""

from __future__ import annotations

import argparse


def reader_options(args: argparse.Namespace) -> dict:
    """The recording reader's options (accelnav.data.inputs.FLAGS: keyword -> flag) from the parsed arguments,
    for the flags this command defines: ``read_input(source, model, **reader_options(args))``."""
    from accelnav.data.inputs import FLAGS  # here, not at the top: the parser stays free of numpy

    return {key: getattr(args, flag) for key, flag in FLAGS.items() if hasattr(args, flag)}


def clock_args(p: argparse.ArgumentParser) -> None:
    """--rate and --time-unit, as every command that reads a recording takes them (one reader, one wording)."""
    p.add_argument(
        "--rate",
        type=float,
        default=None,
        metavar="HZ",
        help="sample rate: without a time column, the rate; with one, the nominal rate it is checked against, "
        "overriding it (samples taken as consecutive, said in a note) where its stamps do not fit",
    )
    p.add_argument(
        "--time-unit",
        choices=("s", "ms", "us", "ns"),
        default=None,
        help="CSV/NPZ: unit of the time column when its name does not say it (t_ms does); default s, or for Unix "
        "time (stamps from 2000 to 2100) the unit its numbers show, said in a note",
    )


# dest -> flag of the options that name a file a command writes; --plots always, and --out for these commands,
# name a folder whose files are each written by the same rule
FILE_OUTPUTS = {"out": "--out", "csv": "--csv", "zupt_report": "--zupt-report"}
FOLDER_OUTPUTS = {"plots": "--plots"}
OUT_FOLDER_COMMANDS = ("codegen", "demo", "hil")
NO_STDOUT = {"record": "a recording goes to a file, a FIFO or a device"}
KEYWORD_INPUTS = {"zupt": ("auto",)}  # options naming an input file unless given one of these words


def outputs_args(args: argparse.Namespace) -> bool:
    """Every output the parsed command names, checked by the output rule (accelnav.fileio.output_target)
    before any work, against every input it names (a file given as both is refused); True when one is
    ``-`` (standard output), the command's own lines then going to stderr."""
    from pathlib import Path

    from accelnav.errors import UserError
    from accelnav.fileio import check_output_folder, output_target

    folders = dict(FOLDER_OUTPUTS)
    files = dict(FILE_OUTPUTS)
    if getattr(args, "command", None) in OUT_FOLDER_COMMANDS:
        folders["out"] = files.pop("out")
    skip = set(files) | set(folders)
    # an option may name one input or several (nargs: a fleet's recordings, --fixes given twice)
    given = [v for k, v in vars(args).items() if k not in skip]
    inputs = [p for v in given for p in (v if isinstance(v, list | tuple) else [v]) if isinstance(p, Path)]
    inputs += [v for k, words in KEYWORD_INPUTS.items() if (v := getattr(args, k, None)) and v not in words]
    stdout = NO_STDOUT.get(getattr(args, "command", None), True)
    to_stdout = None
    for dest, flag in files.items():
        value = getattr(args, dest, None)
        if value is not None and output_target(value, flag, inputs=inputs, stdout=stdout).kind == "stdout":
            if to_stdout:
                raise UserError(f"{flag}: '-' is already {to_stdout}'s; one output at most goes to standard output")
            to_stdout = flag
    for dest, flag in folders.items():
        if getattr(args, dest, None) is not None:
            check_output_folder(getattr(args, dest), flag)
    return to_stdout is not None
