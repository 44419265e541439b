"""``accelnav log info``: a table for a person, JSON for a program, and the two clocks' spans told apart."""

from __future__ import annotations

import json
import re

import pytest
from support.firmware_log import firmware_log

from accelnav.cli import main

N = 1184  # the log: 1 184 samples at 100 Hz are 11.84 s of the device's clock


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    return firmware_log(tmp_path_factory.mktemp("log") / "run.acnlog", "states", True, N)


def test_the_table_has_no_python_reprs_and_says_which_span_is_which(log, capsys):
    assert main(["log", "info", str(log)]) == 0
    out = capsys.readouterr().out
    assert not re.search(r"[\[\]{}]|\bNone\b|'[^'\s]*'", out), out  # no list, dict, None or quoted repr
    rows = dict(re.findall(r"^(\w[\w ]*?)  +(.*)$", out, flags=re.M))
    assert rows["samples"] == f"{N}, sample index 0 .. {N - 1}"
    assert rows["device time"].startswith("11.84 s: the recording's length")
    assert rows["host time"].split(":")[0].endswith(" s") and "not the recording's length" in rows["host time"]
    assert rows["axes"] == "x, y; analog input at 100 Hz" and rows["warnings"] == "none"
    assert rows["frames"].startswith(f"sample {N}, ")


def test_json_keeps_every_field_with_both_spans(log, capsys):
    assert main(["log", "info", str(log), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["device_seconds"] == pytest.approx(N / 100.0)
    assert info["samples"] == N and info["frames"]["sample"] == N and info["axes"] == ["x", "y"]
    assert 0 <= info["host_seconds"] < info["device_seconds"]  # one chunk written at once: arrivals span no time
