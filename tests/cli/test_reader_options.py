"""reader_options: the recording reader's keywords from a command's parsed flags, one table
(accelnav.data.inputs.FLAGS) instead of each command spelling them out."""

from __future__ import annotations

from accelnav.cli import build_parser
from accelnav.cli.args import reader_options
from accelnav.data.inputs import FLAGS


def _opts(argv):
    return reader_options(build_parser(argv[0]).parse_args(argv))


def test_every_reader_flag_a_command_defines_reaches_the_reader():
    got = _opts(["fit-bias", "rec.csv", "--out", "m.toml", "--axis", "ax", "--rate", "200", "--unit", "g",
                 "--time-column", "ms", "--time-unit", "ms"])  # fmt: skip
    assert got == {"axes": ["ax"], "rate_hz": 200.0, "unit": "g", "time_column": "ms", "time_unit": "ms"}
    assert set(got) == set(FLAGS)


def test_a_flag_the_command_lacks_is_left_to_the_readers_default():
    got = _opts(["calibrate", "rec.csv", "--out", "m.toml", "--rate", "50"])
    assert "axes" not in got and got["rate_hz"] == 50.0
