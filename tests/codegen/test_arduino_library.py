"""`accelnav codegen MODEL --arduino DIR`: an Arduino library whose example sketch, built with arduino-mk
against Debian's arduino-core-avr, runs in simavr bit for bit with the firmware in-process (SIL).

The sketch reads both axes with analogRead at each Timer1 tick (the model's rate); simavr's harness
(firmware/boards/atmega328p/simavr_feed.c) gives each conversion the next simulated code of its
channel, rails included, then sends a stop command (it flushes the last block). SIL gets the same
codes as stimulus frames, then the same stop: the telemetry must be the same bytes.

Skipped, with the reason, without avr-gcc, simavr's library or arduino-mk; under
ACCELNAV_REQUIRE_AVR=1 (CI) a failure.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import MODELS

from accelnav.cli import main
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.targets import hil, simavr
from accelnav.hil_sim.targets.firmware import manifest
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.decoder import decode_all
from accelnav.model.load import loads_model

ARDUINO_DIR = Path("/usr/share/arduino")  # Debian's arduino-core-avr and arduino-mk


def _require_arduino():
    try:
        simavr.require_avr()
        simavr.harness()
        if shutil.which("make") is None or not (ARDUINO_DIR / "Arduino.mk").is_file():
            raise simavr.AvrError("arduino-mk not found: install Debian's arduino-mk arduino-core-avr")
    except simavr.AvrError as e:
        if os.environ.get("ACCELNAV_REQUIRE_AVR") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_AVR=1 but {e}")
        pytest.skip(str(e))


def _uno_model(tmp_path: Path) -> Path:
    """The default model read by the Uno's 10-bit ADC."""
    text = (MODELS / "adxl250_default.toml").read_text()
    assert re.search(r"^adc_bits = 12", text, re.M)
    path = tmp_path / "uno.toml"
    path.write_text(re.sub(r"^adc_bits = 12", "adc_bits = 10", text, flags=re.M))
    return path


def test_arduino_example_builds_and_runs_bit_identical_to_sil(tmp_path, capsys):
    _require_arduino()
    path = _uno_model(tmp_path)
    assert main(["codegen", str(path), "--arduino", str(tmp_path / "libs")]) == 0
    lib = tmp_path / "libs" / "accelnav_adxl250_default"
    props = (lib / "library.properties").read_text()
    assert "name=accelnav_adxl250_default" in props and "architectures=avr" in props
    sketch = lib / "examples" / "AccelnavStream"
    assert (sketch / "AccelnavStream.ino").is_file() and (lib / "src" / "accelnav.c").is_file()
    done = subprocess.run(["make", "-s"], cwd=sketch, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    elf = sketch / "build-uno" / "AccelnavStream_.elf"
    # it fits the Uno beside its bootloader (boards.txt: uno.upload.maximum_size)
    boards = (ARDUINO_DIR / "hardware/arduino/avr/boards.txt").read_text()
    limit = re.search(r"^uno\.upload\.maximum_size=(\d+)", boards, re.M)
    size = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True).stdout
    sec = {m[0]: int(m[1]) for m in re.findall(r"^(\.\w+)\s+(\d+)", size, re.M)}
    assert sec[".text"] + sec[".data"] <= int(limit[1])

    model = loads_model(path.read_text(), source=str(path))
    run = simulate(model, "shock", 2.0, seed=9)
    assert run.clipped.any()  # rails: the filter's refusal path, through analogRead too
    man = manifest(model.source)
    stop = encode_command(man, "stop")
    sil = hil.run_sil(model, encode_stimulus(man, code=run.code) + stop)
    pil = simavr.run_feed(elf, stop, adc=run.code, timeout=120)
    frames, stats = decode_all(man, pil.telemetry)
    assert stats.as_dict()["lost"] == 0 and len(frames["block"]) >= len(run.t) // man.data["block_samples"]
    assert pil.telemetry == sil


def test_arduino_refuses_a_model_it_cannot_read_in_one_line(tmp_path, capsys):
    status = main(["codegen", str(MODELS / "adxl250_default.toml"), "--arduino", str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1
    assert "sensor.analog.adc_bits: --arduino reads 10-bit analogRead codes; the model's ADC has 12 bits" in err
    status = main(["codegen", str(MODELS / "adxl202_duty.toml"), "--arduino", str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 2 and "sensor.kind: --arduino reads analogRead" in err and err.count("\n") == 1
    assert not any(tmp_path.iterdir())
    assert main(["codegen", str(MODELS / "adxl250_default.toml")]) == 2
    assert "give --out DIR (the generated C) or --arduino DIR" in capsys.readouterr().err


HOSTILE_NAME = "x:y=z (1)+2, 3.."  # legal for the loader's model-name rule; no C identifier, file or make name


def test_a_model_name_that_is_no_identifier_gives_a_library_with_valid_names(tmp_path, capsys):
    """The library's name (its folder, library.properties, the example's ARDUINO_LIBS) was the model's name
    as given, ':' '=' spaces and all: arduino-mk could not find it. It goes through the C-identifier rule."""
    text = _uno_model(tmp_path).read_text().replace('name = "adxl250_default"', f'name = "{HOSTILE_NAME}"', 1)
    path = tmp_path / "hostile.toml"
    path.write_text(text)
    assert loads_model(text, source=str(path)).name == HOSTILE_NAME
    assert main(["codegen", str(path), "--arduino", str(tmp_path / "libs")]) == 0
    (lib,) = (tmp_path / "libs").iterdir()
    ident = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}")
    assert ident.fullmatch(lib.name) and lib.name.startswith("accelnav_x_y_z_1_2_3_"), lib.name
    props = dict(line.split("=", 1) for line in (lib / "library.properties").read_text().splitlines() if line)
    assert props["name"] == lib.name
    sketch = lib / "examples" / "AccelnavStream"
    assert f"ARDUINO_LIBS = {lib.name}\n" in (sketch / "Makefile").read_text()
    for f in lib.rglob("*"):
        assert re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.]*", f.name), f
    # the name is still shown as the user wrote it where text may hold it (a comment, the description)
    assert f"model {HOSTILE_NAME}." in props["sentence"]
    assert f"model '{HOSTILE_NAME}'" in (sketch / "AccelnavStream.ino").read_text()
    _require_arduino()
    done = subprocess.run(["make", "-s"], cwd=sketch, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (sketch / "build-uno" / "AccelnavStream_.elf").is_file()


def test_the_library_name_rule_keeps_names_apart():
    from accelnav.model.load import c_identifier_from, name_problem

    assert c_identifier_from("adxl250_default", "accelnav_") == "accelnav_adxl250_default"  # a clean name as is
    a, b = c_identifier_from("a b", "accelnav_"), c_identifier_from("a:b", "accelnav_")
    assert a != b and a.startswith("accelnav_a_b_")
    for name in (HOSTILE_NAME, "9" * 64, "(((", "a" * 64):
        got = c_identifier_from(name, "accelnav_")
        assert name_problem("C prefix", got) is None and len(got) <= 32, got
