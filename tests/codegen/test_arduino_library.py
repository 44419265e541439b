"""`accelnav codegen MODEL --arduino DIR`: an Arduino library whose example sketches, built with arduino-mk
against Debian's arduino-core-avr, run in simavr: the streaming one bit for bit with the firmware
in-process (SIL), the Serial Plotter one printing the host's positions digit for digit.

AccelnavStream reads both axes with analogRead at each Timer1 tick (the model's rate); simavr's harness
(firmware/boards/atmega328p/simavr_feed.c) gives each conversion the next simulated code of its
channel, rails included, then sends a stop command (it flushes the last block). SIL gets the same
codes as stimulus frames, then the same stop: the telemetry must be the same bytes. AccelnavPlotter
samples on micros() and prints a line of positions per sample: the host's firmware gives every sample's
state (the state mode), printed by the rule the library states (AccelNav.cpp, acn_print_fixed).

Skipped, with the reason, without avr-gcc, simavr's library or arduino-mk; under
ACCELNAV_REQUIRE_AVR=1 (CI) a failure.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import MODELS

from accelnav.cli import main
from accelnav.codegen import targets
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.targets import hil, simavr
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.decoder import decode_all
from accelnav.model.load import loads_model

ARDUINO_DIR = Path("/usr/share/arduino")  # Debian's arduino-core-avr and arduino-mk
WHO = ["--maintainer", "Ada Lovelace <ada@example.org>", "--url", "https://example.org/accelnav"]


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


def _uno_model(tmp_path: Path, ref_v: float | None = None) -> Path:
    """The default model read by the Uno's 10-bit ADC; ``ref_v``: an ADC reference on AREF (the sensor's zero
    at half of it, ratiometric as an ADXL335 on 3.3 V)."""
    text = (MODELS / "adxl250_default.toml").read_text()
    assert re.search(r"^adc_bits = 12", text, re.M)
    text = re.sub(r"^adc_bits = 12", "adc_bits = 10", text, flags=re.M)
    if ref_v is not None:
        for key, value in (("supply_v", ref_v), ("adc_ref_v", ref_v), ("zero_g_v", ref_v / 2),
                           ("sensitivity_v_per_g", 0.038 * ref_v / 5.0)):  # fmt: skip
            text = re.sub(rf"^{key} = .*$", f"{key} = {value:.6g}", text, flags=re.M)
    path = tmp_path / f"uno{'' if ref_v is None else '_ref'}.toml"
    path.write_text(text)
    return path


def _make(sketch: Path) -> Path:
    done = subprocess.run(["make", "-s"], cwd=sketch, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    (elf,) = sketch.glob("build-uno/*.elf")
    return elf


def _sections(elf: Path) -> dict[str, int]:
    size = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True).stdout
    return {m[0]: int(m[1]) for m in re.findall(r"^(\.\w+)\s+(\d+)", size, re.M)}


def test_arduino_example_builds_and_runs_bit_identical_to_sil(tmp_path, capsys):
    _require_arduino()
    path = _uno_model(tmp_path)
    assert main(["codegen", str(path), "--arduino", str(tmp_path / "libs"), *WHO]) == 0
    said = capsys.readouterr().out
    lib = tmp_path / "libs" / "accelnav_adxl250_default"
    props = (lib / "library.properties").read_text()
    assert "name=accelnav_adxl250_default" in props and "architectures=avr" in props
    sketch = lib / "examples" / "AccelnavStream"
    assert (sketch / "AccelnavStream.ino").is_file() and (lib / "src" / "accelnav.c").is_file()
    elf = _make(sketch)
    # it fits the Uno beside its bootloader (boards.txt: uno.upload.maximum_size), and codegen said so, with
    # the sizes of this very link
    boards = (ARDUINO_DIR / "hardware/arduino/avr/boards.txt").read_text()
    limit = re.search(r"^uno\.upload\.maximum_size=(\d+)", boards, re.M)
    sec = _sections(elf)
    assert sec[".text"] + sec[".data"] <= int(limit[1])
    m = re.search(r"^  AccelnavStream +flash (\d+) B, RAM (\d+) B: fits$", said, re.M)
    assert m, said
    assert (int(m[1]), int(m[2])) == (sec[".text"] + sec[".data"], sec[".data"] + sec.get(".bss", 0))

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
    # the stack the fit check keeps free (the firmware's, parts.mk) holds the sketch's deepest stack too
    assert 0 < pil.stack <= targets.part("atmega328p").stack, pil.stack


def _fixed(v: int, frac: int) -> str:
    """The library's decimal of v * 2^-frac (AccelNav.cpp, acn_print_fixed), for the host's states."""
    m = abs(v)
    whole, micro = m, 0
    if frac > 0:
        whole = m >> frac
        part = m - (whole << frac)
        if frac > 43:
            part >>= frac - 43
            frac = 43
        micro = (part * 1_000_000 + (1 << (frac - 1))) >> frac
        if micro >= 1_000_000:
            whole, micro = whole + 1, micro - 1_000_000
    whole = min(whole, 2**32 - 1)
    return f"{'-' if v < 0 and (whole or micro) else ''}{whole}.{micro:06d}"


def test_the_fixed_point_print_rule():
    assert _fixed(3 << 40, 40) == "3.000000" and _fixed(-(1 << 39), 40) == "-0.500000"
    assert _fixed(-1, 40) == "0.000000"  # rounds to zero: no sign
    assert _fixed((1 << 40) - 1, 40) == "1.000000"  # the carry into the whole part
    assert _fixed(1 << 62, 10) == "4294967295.000000"  # the whole part saturates


def _plotter_run(tmp_path: Path, path: Path, n: int):
    assert main(["codegen", str(path), "--arduino", str(tmp_path / "libs"), *WHO, "--board", "none"]) == 0
    model = loads_model(path.read_text(), source=str(path))
    (lib,) = (tmp_path / "libs").iterdir()
    elf = _make(lib / "examples" / "AccelnavPlotter")
    run = simulate(model, "shock", n / model.rate_hz, seed=9)
    return model, run, simavr.run_feed(elf, b"", adc=run.code, timeout=300)


def test_the_plotter_example_prints_the_hosts_positions(tmp_path):
    """AccelnavPlotter: the class on the sketch's own schedule, one text line of positions per sample; each
    line is the host firmware's state of that sample printed by the library's rule, digit for digit."""
    _require_arduino()
    model, run, pil = _plotter_run(tmp_path, _uno_model(tmp_path), 200)
    assert run.clipped.any()  # rails: refused inputs, predicted over, on the sketch too
    man = manifest(model.source)
    fw = HostFirmware(build_firmware(model.source))
    fw.rx(encode_command(man, "mode_states") + encode_stimulus(man, code=run.code))
    states = decode_all(man, fw.take())[0]["sample"]
    assert len(states) == len(run.code)
    axes = [a.name for a in model.axes]
    frac = {a: man.field("sample", f"{a}.r")["frac"] for a in axes}
    want = [" ".join(f"{a}:{_fixed(int(s[f'{a}.r']), frac[a])}" for a in axes) for s in states]
    lines = pil.telemetry.decode("ascii").split("\r\n")
    assert lines[: len(want)] == want
    assert any(float(v.split(":")[1]) != 0.0 for v in want[-1].split())  # the shock moved something
    assert pil.refs == 1  # a 5 V reference: the Uno's default, AVCC
    assert 0 < pil.stack <= targets.part("atmega328p").stack, pil.stack


def test_a_model_with_a_3v3_reference_selects_the_external_reference(tmp_path):
    """adc_ref_v = 3.3 (AREF wired to 3.3 V, as for an ADXL335): begin() selects the external reference
    before the first conversion (ADMUX's REFS bits 00 in simavr), not the 5 V default (01)."""
    _require_arduino()
    _, _, pil = _plotter_run(tmp_path, _uno_model(tmp_path, ref_v=3.3), 5)
    assert pil.refs == 0


def test_the_library_exports_only_prefixed_names(tmp_path, capsys):
    """Every global symbol the library's objects define starts with acn, accelnav or AccelNav (C++ names
    demangled): none collides with another library's app, link_send, cobs_encode or crc32_update. Each
    source compiled for the Uno against the core's headers, without LTO, and read with avr-nm."""
    _require_arduino()
    assert main(["codegen", str(_uno_model(tmp_path)), "--arduino", str(tmp_path / "libs"), *WHO, "--board",
                 "none"]) == 0  # fmt: skip
    (lib,) = (tmp_path / "libs").iterdir()
    core = ARDUINO_DIR / "hardware/arduino/avr"
    inc = ["-I", str(core / "cores/arduino"), "-I", str(core / "variants/standard"), "-I", str(lib / "src")]
    names = []
    sources = sorted(lib.glob("src/*.c")) + sorted(lib.glob("src/*.cpp"))
    assert {p.name for p in sources} >= {"acn_app.c", "acn_link.c", "acn_cobs.c", "acn_crc32.c", "AccelNav.cpp"}
    assert not any(p.name in ("app.h", "link.h", "crc32.h", "cobs.h") for p in lib.glob("src/*"))
    for src in sources:
        cc = ["avr-g++", "-std=gnu++11"] if src.suffix == ".cpp" else ["avr-gcc", "-std=gnu11"]
        obj = tmp_path / (src.name + ".o")
        cmd = [*cc, "-mmcu=atmega328p", "-DF_CPU=16000000UL", "-DARDUINO=10819", "-DDECIMAL_DIG=__DECIMAL_DIG__", "-Os"]
        done = subprocess.run([*cmd, *inc, "-c", str(src), "-o", str(obj)], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr[-2000:]
        nm = subprocess.run(["avr-nm", "-C", "-g", "--defined-only", str(obj)], capture_output=True, text=True,
                            check=True).stdout  # fmt: skip
        names += [line.split(maxsplit=2)[2] for line in nm.splitlines() if line.strip()]
    assert "acn_app" in names and "acn_link_send" in names and "AccelNav::begin()" in names
    bad = [n for n in names if not re.match(r"(acn|accelnav|AccelNav)", n)]
    assert bad == []


def test_arduino_refuses_a_model_it_cannot_read_in_one_line(tmp_path, capsys):
    status = main(["codegen", str(MODELS / "adxl250_default.toml"), "--arduino", str(tmp_path), *WHO])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1
    assert "sensor.analog.adc_bits: --arduino reads 10-bit analogRead codes; the model's ADC has 12 bits" in err
    status = main(["codegen", str(MODELS / "adxl202_duty.toml"), "--arduino", str(tmp_path), *WHO])
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
    assert main(["codegen", str(path), "--arduino", str(tmp_path / "libs"), *WHO, "--board", "none"]) == 0
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
    _make(sketch)


def test_the_library_name_rule_keeps_names_apart():
    from accelnav.model.load import c_identifier_from, name_problem

    assert c_identifier_from("adxl250_default", "accelnav_") == "accelnav_adxl250_default"  # a clean name as is
    a, b = c_identifier_from("a b", "accelnav_"), c_identifier_from("a:b", "accelnav_")
    assert a != b and a.startswith("accelnav_a_b_")
    for name in (HOSTILE_NAME, "9" * 64, "(((", "a" * 64):
        got = c_identifier_from(name, "accelnav_")
        assert name_problem("C prefix", got) is None and len(got) <= 32, got


def test_a_sketch_that_would_not_fit_the_uno_is_refused_in_one_line(tmp_path, capsys):
    """`--arduino --board uno` links the example sketches before writing anything: the gain schedule's tables
    do not fit beside the bootloader, and the refusal states the linked size."""
    _require_arduino()
    argv = ["codegen", str(_uno_model(tmp_path)), "--arduino", str(tmp_path / "libs"), *WHO, "--board", "uno"]
    status = main([*argv, "--form", "gain_schedule"])
    err = capsys.readouterr().err
    m = re.search(r"--board uno: the AccelnavStream sketch does not fit: needs (\d+) B flash of 32256 \(linked\)", err)
    assert status == 2 and err.count("\n") == 1 and m, err
    assert int(m[1]) > 32256
    assert not (tmp_path / "libs").exists()


PROBE = r"""/* a test's sketch: the class' text telemetry, then its numbers as float bits and its status */
#include <AccelNav.h>
#include <string.h>

AccelNav nav;

static void bits(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    Serial.print(' ');
    Serial.print(u, HEX);
}

void setup()
{
    Serial.begin(500000);
    nav.begin(Serial, AccelNav::TEXT);
}

void loop()
{
    if (nav.due()) {
        nav.update();
        Serial.print(nav.status());
        for (uint8_t i = 0; i < AccelNav::AXES; ++i) {
            bits(nav.position(i));
            bits(nav.velocity(i));
            bits(nav.acceleration(i));
            bits(nav.bias(i));
        }
        Serial.println();
    }
}
"""


def test_the_class_gives_the_hosts_states_as_numbers_and_its_status(tmp_path):
    """A sketch of the test's own on the class: begin(Serial, TEXT) prints the positions' line at each
    update(), and position, velocity, acceleration and bias are the host firmware's states as float32 (the
    fixed-point value rounded once, bit for bit); status() says REFUSED exactly at the samples whose input
    hit a rail, and nothing else."""
    _require_arduino()
    path = _uno_model(tmp_path)  # one axis (x): the probe's printing beside two filters passes the Uno's flash
    path.write_text(re.sub(r'\n\[\[axes\]\]\nname = "y".*?(?=\n\[noise\])', "", path.read_text(), flags=re.S))
    assert main(["codegen", str(path), "--arduino", str(tmp_path / "libs"), *WHO, "--board", "none"]) == 0
    (lib,) = (tmp_path / "libs").iterdir()
    sketch = lib / "examples" / "Probe"
    sketch.mkdir()
    (sketch / "Probe.ino").write_text(PROBE)
    (sketch / "Makefile").write_text((lib / "examples" / "AccelnavPlotter" / "Makefile").read_text())
    elf = _make(sketch)
    model = loads_model(path.read_text(), source=str(path))
    run = simulate(model, "shock", 1.5, seed=5)
    assert run.clipped.any()
    pil = simavr.run_feed(elf, b"", adc=run.code, timeout=300)
    man = manifest(model.source)
    fw = HostFirmware(build_firmware(model.source))
    fw.rx(encode_command(man, "mode_states") + encode_stimulus(man, code=run.code))
    states = decode_all(man, fw.take())[0]["sample"]
    axes = [a.name for a in model.axes]
    frac = {(a, s): man.field("sample", f"{a}.{s}")["frac"] for a in axes for s in "ruae"}
    lines = pil.telemetry.decode("ascii").split("\r\n")[: 2 * len(states)]
    assert len(lines) == 2 * len(states)
    refused = 0
    for k, s in enumerate(states):
        text, numbers = lines[2 * k], lines[2 * k + 1].split()
        assert text == " ".join(f"{a}:{_fixed(int(s[f'{a}.r']), frac[a, 'r'])}" for a in axes)
        hit = any(int(s[f"{a}.flags"]) & 1 for a in axes)  # ACNF_AXIS_SKIPPED: a rail, predicted over
        assert int(numbers[0]) == (1 if hit else 0), (k, numbers[0])  # AccelNav::REFUSED
        refused += hit
        want = [
            np.int64(s[f"{a}.{q}"]).astype(np.float32) * np.float32(2.0 ** -frac[a, q]) for a in axes for q in "ruae"
        ]
        got = [np.frombuffer(int(h, 16).to_bytes(4, "little"), "<f4")[0] for h in numbers[1:]]
        assert [w.tobytes() for w in want] == [g.tobytes() for g in got], k
    assert refused > 0
