"""The firmware cache under two builders, and the simavr feed program kept in the cache (issue 30).
Before: two test suites at once ended in "no firmware image (build it with 'make firmware
BOARD=atmega328p')": two makes in one folder relinked the image under each other."""

from __future__ import annotations

import shutil
import subprocess
import sys
import time

import pytest
from support.cachekey import private_cache, seal_with_other_key

from accelnav.cachefile import entry_lock
from accelnav.hil_sim.targets import simavr

BUILD = (
    "import sys; from accelnav.hil_sim.targets.firmware import make_firmware; make_firmware('host', None, sys.argv[1])"
)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    if shutil.which("cc") is None or shutil.which("make") is None:
        pytest.skip("the host board needs cc and make (Debian: gcc make)")
    return private_cache(tmp_path, monkeypatch)


def _start(out):
    return subprocess.Popen([sys.executable, "-c", BUILD, str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def test_a_second_build_of_one_image_waits_for_the_first(cache, tmp_path):
    out = tmp_path / "fw"
    with entry_lock(out):  # a build in progress
        child = _start(out)
        time.sleep(3.0)
        assert child.poll() is None, "the second build did not wait"
        assert not (out / "accelnav_fw").exists()
    assert child.wait(300) == 0, child.stderr.read().decode()[-2000:]
    assert (out / "accelnav_fw").is_file() and (out / "size.txt").read_text().strip()


def test_two_builders_of_one_image_both_get_it_whole(cache, tmp_path):
    out = tmp_path / "fw"
    procs = [_start(out) for _ in range(2)]
    for p in procs:
        assert p.wait(300) == 0, p.stderr.read().decode()[-2000:]
    image = out / "accelnav_fw"
    assert image.is_file() and image.read_bytes()[:4] == b"\x7fELF"


def test_a_feed_program_replaced_in_the_cache_is_never_run(tmp_path, monkeypatch, capfd):
    cache = private_cache(tmp_path, monkeypatch)
    try:
        good = simavr.harness()
    except simavr.AvrError as e:
        pytest.skip(str(e))
    (entry,) = [p for p in (cache / "simavr").glob("simavr_feed-*") if p.suffix != ".lock"]
    marker = tmp_path / "MARKER"
    hostile = f"#!/bin/sh\ntouch {marker}\n".encode()
    seal_with_other_key(entry, hostile, tmp_path, monkeypatch)
    assert simavr.harness() == good
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and f"cache entry {entry}: its seal does not verify" in err
    entry.write_bytes(entry.read_bytes()[:40] + hostile)  # our header, their program
    assert simavr.harness() == good and not marker.exists()
