"""Firmware images and the simavr feed program in the cache (issue 30). Before: a board's image folder was
built in place by make and trusted as found (a planted object or image ran under the emulator, whose
semihosting can touch host files), and two test suites at once ended in "no firmware image (build it with
'make firmware BOARD=atmega328p')". Now an image is built in a private folder, sealed, verified before
every use and run from a private copy; one that does not verify is rebuilt with one line, never run."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest
from support.cachekey import private_cache, seal_with_other_key
from support.said import listen, one_warning

from accelnav.cachefile import HEAD, entry_lock
from accelnav.hil_sim.targets import firmware, simavr
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.resources import models_dir

# a builder in another process; says BUILT each time it runs make
BUILD = (
    "import sys; from accelnav.hil_sim.targets import firmware as f; b = f._build; "
    "f._build = lambda *a: (print('BUILT', flush=True), b(*a))[1]; f.make_firmware('host', None, sys.argv[1])"
)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    if shutil.which("cc") is None or shutil.which("make") is None:
        pytest.skip("the host board needs cc and make (Debian: gcc make)")
    return private_cache(tmp_path, monkeypatch)


def _start(out):
    return subprocess.Popen(
        [sys.executable, "-c", BUILD, str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _run_host(folder, tmp_path) -> bytes:
    """The host board's program in ``folder`` fed 300 samples, as a PIL run feeds an emulated board, each
    run in a folder of its own (the board keeps its boot count in its working folder)."""
    man = firmware.manifest()
    code = 2048 + np.random.default_rng(3).integers(-30, 30, (300, 2))
    stdin = encode_stimulus(man, code=code) + encode_command(man, "flush")  # no info: it says the uptime
    done = subprocess.run([folder / "accelnav_fw"], input=stdin, capture_output=True, timeout=60,
                          cwd=tempfile.mkdtemp(dir=tmp_path))  # fmt: skip
    assert done.returncode == 0 and len(done.stdout) > 300
    return done.stdout


def test_a_second_build_of_one_image_waits_for_the_first(cache, tmp_path):
    out = tmp_path / "fw"
    with entry_lock(firmware.image_entry("host")):  # a build in progress
        child = _start(out)
        time.sleep(3.0)
        assert child.poll() is None, "the second build did not wait"
        assert not (out / "accelnav_fw").exists()
    assert child.wait(300) == 0, child.stderr.read()[-2000:]
    assert (out / "accelnav_fw").is_file() and (out / "size.txt").read_text().strip()


def test_two_builders_of_one_image_build_once_and_both_get_it_whole(cache, tmp_path):
    procs = [_start(tmp_path / f"fw{i}") for i in range(2)]
    said = []
    for p in procs:
        assert p.wait(300) == 0, p.stderr.read()[-2000:]
        said.append(p.stdout.read())
    assert "".join(said).count("BUILT") == 1, said
    a, b = ((tmp_path / f"fw{i}" / "accelnav_fw").read_bytes() for i in range(2))
    assert a[:4] == b"\x7fELF" and a == b


def test_an_image_replaced_in_the_cache_is_never_run(cache, tmp_path, capfd, caplog):
    listen(caplog)
    with firmware.private_firmware("host") as fw:
        clean = _run_host(fw, tmp_path)
    entry = firmware.image_entry("host")
    good = entry.read_bytes()
    marker = tmp_path / "MARKER"
    hostile = firmware._pack({"accelnav_fw": f"#!/bin/sh\ntouch {marker}\n".encode(), "size.txt": b"1\n"})
    capfd.readouterr()
    for planted in (
        lambda: seal_with_other_key(entry, hostile, tmp_path, pytest.MonkeyPatch()),  # their key
        lambda: entry.write_bytes(good[:HEAD] + hostile),  # our header, their image
    ):
        planted()
        with firmware.private_firmware("host") as fw:
            assert _run_host(fw, tmp_path) == clean
        assert capfd.readouterr().err == ""  # the warning is logged: nothing else on stderr
        line = one_warning(caplog)
        assert f"cache entry {entry}: its seal does not verify" in line, line
        assert line.endswith("; rebuilt") and not marker.exists()


def test_a_valid_image_of_another_model_in_its_place_is_rebuilt(cache, tmp_path, capfd, caplog):
    listen(caplog)
    duty = models_dir() / "adxl202_duty.toml"
    other = firmware.image_entry("host", duty)
    firmware.firmware_images("host", duty)  # a valid image, sealed under our key, for another model
    with firmware.private_firmware("host") as fw:
        clean = _run_host(fw, tmp_path)
    entry = firmware.image_entry("host")
    shutil.copyfile(other, entry)
    capfd.readouterr()
    with firmware.private_firmware("host") as fw:
        assert _run_host(fw, tmp_path) == clean
    assert capfd.readouterr().err == ""  # the warning is logged: nothing else on stderr
    line = one_warning(caplog)
    assert f"cache entry {entry}: its seal does not verify" in line and "rebuilt" in line


def test_a_truncated_image_is_rebuilt(cache, tmp_path, capfd, caplog):
    listen(caplog)
    with firmware.private_firmware("host") as fw:
        clean = _run_host(fw, tmp_path)
    entry = firmware.image_entry("host")
    with open(entry, "r+b") as fh:
        fh.truncate(entry.stat().st_size // 2)
    capfd.readouterr()
    with firmware.private_firmware("host") as fw:  # a new build: the same program (its bytes name its folder)
        assert _run_host(fw, tmp_path) == clean
    assert capfd.readouterr().err == ""  # the warning is logged: nothing else on stderr
    line = one_warning(caplog)
    assert f"cache entry {entry}: its seal does not verify" in line and "rebuilt" in line
    entry.write_bytes(entry.read_bytes()[: HEAD - 1])  # shorter than a seal
    firmware.firmware_images("host")
    assert capfd.readouterr().err == ""  # the warning is logged: nothing else on stderr
    line = one_warning(caplog)
    assert f"cache entry {entry}: not a sealed entry ({HEAD - 1} bytes" in line, line


def test_a_feed_program_replaced_in_the_cache_is_never_run(tmp_path, monkeypatch, capfd, caplog):
    listen(caplog)
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
    assert capfd.readouterr().err == ""  # the warning is logged: nothing else on stderr
    line = one_warning(caplog)
    assert f"cache entry {entry}: its seal does not verify" in line
    entry.write_bytes(entry.read_bytes()[:40] + hostile)  # our header, their program
    assert simavr.harness() == good and not marker.exists()


def test_pil_runs_only_the_sealed_image_of_its_model(tmp_path, monkeypatch, capfd, caplog):
    """The emulated board, whose semihosting reaches host files: a valid image of another model planted in
    the cache is rebuilt, and the run equals SIL bit for bit."""
    listen(caplog)
    if shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("PIL on mps2_an385 needs qemu-system-arm and arm-none-eabi-gcc")
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.hil_sim.targets import hil
    from accelnav.model.load import load_model

    private_cache(tmp_path, monkeypatch)
    duty = models_dir() / "adxl202_duty.toml"
    firmware.firmware_images("mps2_an385", duty)
    model = load_model()
    run = simulate(model, "shock", 1.0, seed=2)
    stim = hil.stimulus(firmware.manifest(model.source), run)
    sil = hil.run_sil(model, stim)
    entry = firmware.image_entry("mps2_an385", model.source)
    entry.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(firmware.image_entry("mps2_an385", duty), entry)
    capfd.readouterr()
    pil = hil.run_pil(model, stim, len(run.t), tmp_path / "p.acnlog", board="mps2_an385")
    assert pil.telemetry == sil
    assert capfd.readouterr().err == ""  # the warning is logged: nothing else on stderr
    line = one_warning(caplog)
    assert f"cache entry {entry}: its seal does not verify" in line and "rebuilt" in line
