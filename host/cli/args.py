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
        choices=("s", "ms", "us"),
        default=None,
        help="CSV/NPZ: unit of the time column when its name does not say it (t_ms does); default s",
    )
