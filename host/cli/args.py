"""Argument groups more than one command takes, defined once so that their names and help agree."""

from __future__ import annotations

import argparse


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
