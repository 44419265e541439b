"""An Arduino library of a model: ``accelnav codegen MODEL --arduino DIR``.

:func:`library` returns ``{path in the library folder: text}`` in Arduino's layout (1.5 format) and
PlatformIO's: ``library.properties`` and ``library.json``, ``README.md``, ``LICENSE``,
``keywords.txt``; ``src/`` with the class a sketch calls (``AccelNav.h``: begin, update, position,
velocity, bias, status), the generated filter (accelnav.*) and frame code (acnframe.*), and the
firmware's board-independent application (firmware/src: compact telemetry, commands, framing) under
prefixed names; ``examples/`` with two sketches, each with an arduino-mk Makefile and a
``platformio.ini``: AccelnavStream (Timer1 chosen by the sketch, the firmware's binary telemetry, which
``accelnav record`` reads with ``extras/acnframe.json``) and AccelnavPlotter (the sketch's own schedule by
micros(), a text line of positions for the Serial Plotter). Only the CLI writes files.

Every global name the library exports starts with ``acn``, ``accelnav`` or ``AccelNav``, and so does every
header: the firmware's sources keep their names in the project (its boards use them) and are renamed as
they are copied: ``app.h`` becomes ``acn_app.h``, and ``acn_names.h`` (generated, included first) maps
``app_init`` to ``acn_app_init`` and so on, the way zlib's Z_PREFIX does.

The sketch reads 10-bit codes (analogRead), on pins A0, A1, ... in axis order: a model whose input is
not a 10-bit ADC is refused in one line (ModelError), as the Uno has six analog pins. The ADC reference
follows the model's ``adc_ref_v``: 5 V is the Uno's default (AVCC), 1.1 V its internal reference, any
other value up to 5 V an external one on AREF (``analogReference(EXTERNAL)``, the wiring in the README).
"""

from __future__ import annotations

import json
import re

from accelnav.model.load import Model, ModelError, c_identifier_from
from accelnav.resources import firmware_dir

from .generated import generate
from .package import GENERATOR_VERSION, banner

EXAMPLES = ("AccelnavStream", "AccelnavPlotter")
EXAMPLE = EXAMPLES[0]
ANALOG_PINS = 6  # A0..A5 on an Uno
UNO_VCC = 5.0  # the Uno's AVCC: its default reference, and the most AREF may take
UNO_INTERNAL = 1.1  # the ATmega328P's internal reference
# the firmware's sources (firmware/src) and the names they export; each is renamed acn_NAME in the library
APP_SOURCES = ("app", "filter_adapter", "link", "cobs", "crc32")
APP_GLOBALS = (
    "app", "app_init", "app_sample", "app_missed", "app_rx", "app_overflow_total",
    "link_rx_init", "link_rx_byte", "link_send", "link_frame", "cobs_encode", "cobs_decode", "crc32_update",
    "board_init", "board_poll", "board_uart_write", "board_time_ms", "board_id", "board_boot_id", "board_rx_lost",
)  # fmt: skip
_INCLUDE = re.compile(r'^#include "(' + "|".join(APP_SOURCES) + r')\.h"', re.M)


def library_name(model: Model) -> str:
    """The library's name, which is also its folder's and what a Makefile's ARDUINO_LIBS names: the model's name
    (which may hold spaces, ':', '=', ...) through the C-identifier rule."""
    return c_identifier_from(model.name, "accelnav_")


def reference(model: Model) -> tuple[str, str]:
    """The analogReference() argument the model's adc_ref_v asks for on an Uno, and the wiring it needs
    (one sentence for the README); ModelError for a reference above the supply."""
    v = model.sensor.analog.adc_ref_v
    if abs(v - UNO_VCC) < 1e-9:
        return "DEFAULT", f"The ADC reference is the Uno's {UNO_VCC:g} V supply (AVCC, the default): leave AREF open."
    if abs(v - UNO_INTERNAL) < 1e-9:
        return "INTERNAL", f"The ADC reference is the ATmega328P's internal {UNO_INTERNAL:g} V: leave AREF open."
    if v > UNO_VCC:
        raise ModelError(model.source, "sensor.analog.adc_ref_v", f"--arduino: an external reference of {v:g} V on "
                         f"AREF is above the Uno's {UNO_VCC:g} V supply (it would damage the ATmega328P)")  # fmt: skip
    return "EXTERNAL", (
        f"The model's ADC reference is {v:g} V: wire AREF to a {v:g} V source (for an ADXL335 on 3.3 V, its "
        "supply pin). `begin()` selects the external reference (`analogReference(EXTERNAL)`) before the first "
        "`analogRead`; a sketch that calls `analogRead` before `begin()` drives AVCC against AREF and can damage "
        "the chip."
    )


def _refuse(model: Model) -> None:
    sensor = model.sensor
    if sensor.kind != "analog":
        raise ModelError(model.source, "sensor.kind", f"--arduino reads analogRead; got {sensor.kind!r}, "
                         "whose input is a timer capture (not in the Arduino library)")  # fmt: skip
    if sensor.analog.adc_bits != 10:
        raise ModelError(model.source, "sensor.analog.adc_bits", f"--arduino reads 10-bit analogRead codes; the "
                         f"model's ADC has {sensor.analog.adc_bits} bits (set adc_bits = 10 for an Uno)")  # fmt: skip
    n = len(model.axes)
    if n > ANALOG_PINS:
        raise ModelError(model.source, "axes", f"--arduino: {n} axes, an Uno has {ANALOG_PINS} analog pins")


def _prefixed(text: str, source: bool) -> str:
    """A firmware source as the library holds it: its includes of the firmware's headers renamed, and (a .c
    file) the name map included first."""
    text = _INCLUDE.sub(r'#include "acn_\1.h"', text)
    if source:
        text = "#include \"acn_names.h\" /* this library's prefixed names of the firmware's globals */\n" + text
    return text


def _names_h(model: Model) -> str:
    head = banner("acn_names.h: the firmware's global names, prefixed in this library", "accelnav codegen "
                  f"{GENERATOR_VERSION} --arduino", model.name, model.sha256)  # fmt: skip
    lines = [head + "#ifndef ACN_NAMES_H", "#define ACN_NAMES_H", ""]
    lines += [f"#define {g} acn_{g}" for g in APP_GLOBALS]
    lines += ["", "/* the sketch reads its own ADC: no stimulus link, one receive buffer less (acn_board.h) */",
              "#define ACN_NO_STIM_CHANNEL 1"]  # fmt: skip
    return "\n".join(lines + ["", "#endif", ""])


def _model_h(model: Model, aref: str, wiring: str) -> str:
    head = banner("acn_model.h: the board facts of the model (pins, ADC reference)", "accelnav codegen "
                  f"{GENERATOR_VERSION} --arduino", model.name, model.sha256)  # fmt: skip
    pins = ", ".join(f"A{i}" for i in range(len(model.axes)))
    return "\n".join([
        head + "#ifndef ACN_MODEL_H", "#define ACN_MODEL_H", "",
        f"/* adc_ref_v {model.sensor.analog.adc_ref_v:g} V: analogReference({aref}) in begin() (README.md) */",
        f"#define ACN_AREF {aref}",
        f"#define ACN_PINS {{{pins}}} /* axis order: {', '.join(a.name for a in model.axes)} */",
        "", "#endif", "",
    ])  # fmt: skip


def _makefile(name: str) -> str:
    return (
        "# arduino-mk (Debian: arduino-mk arduino-core-avr): `make` builds build-uno/, `make upload` flashes it\n"
        "BOARD_TAG = uno\n"
        f"ARDUINO_LIBS = {name}\n"
        "USER_LIB_PATH := $(realpath ../../..)\n"
        "ARDUINO_DIR ?= /usr/share/arduino\n"
        "# Debian's arduino-core-avr 1.8 expects avr-gcc 7, whose <float.h> has C++11's DECIMAL_DIG (5.4's has not)\n"
        "CXXFLAGS += -DDECIMAL_DIG=__DECIMAL_DIG__\n"
        "# shared register save/restore: about 600 B less, what a 2-axis model needs to fit the Uno beside its\n"
        "# bootloader (32256 B); the IDE cannot pass this flag (firmware/README.md)\n"
        "CFLAGS += -mcall-prologues\n"
        "CXXFLAGS += -mcall-prologues\n"
        "LDFLAGS += -mcall-prologues\n"
        "# `accelnav codegen --arduino DIR --board uno` links with the flash region raised (ACN_LDFLAGS), so that\n"
        "# a sketch too big still links and its size can be stated\n"
        "LDFLAGS += $(ACN_LDFLAGS)\n"
        "include $(ARDUINO_DIR)/Arduino.mk\n"
    )


def _platformio_ini(name: str) -> str:
    return (
        "; PlatformIO: `pio run` here builds this example for an Uno with the library two folders up\n"
        "[platformio]\n"
        "src_dir = .\n"
        "\n"
        "[env:uno]\n"
        "platform = atmelavr\n"
        "board = uno\n"
        "framework = arduino\n"
        "lib_extra_dirs = ../../..\n"
        f"lib_deps = {name}\n"
        "monitor_speed = 115200\n"
        "build_flags = -mcall-prologues\n"
    )


def _readme(model: Model, name: str, wiring: str) -> str:
    axes = ", ".join(f"{a.name} on A{i}" for i, a in enumerate(model.axes))
    return f"""# {name}

Position, velocity and bias of an analog accelerometer on an Arduino Uno: a fixed-point Kalman filter
per axis, generated by `accelnav codegen --arduino` from the model `{model.name}` (sha256
`{model.sha256[:16]}`...). Do not edit: regenerate it from the model.

## Wiring

Axes {axes}: each output to its analog pin, the sensor's ground to GND. {wiring}

## Use

```cpp
#include <AccelNav.h>
AccelNav nav;

void setup() {{ nav.begin(); }}

void loop() {{
    if (nav.due()) {{           // once per sample period of the model ({model.rate_hz:g} Hz), by micros()
        nav.update();          // analogRead of every axis, one filter step
        float x = nav.position(0);   // metres; velocity(axis) m/s, bias(axis) m/s^2
    }}
}}
```

- Your own codes: `nav.update(codes)` with one 10-bit code per axis; `nav.missed(n)` when n sample periods
  passed unread (the filters predict over them).
- A timer you choose: `nav.tick()` from its interrupt once per period and `nav.poll()` in `loop()`.
  `nav.startTimer1()` sets Timer1 up for it; then Servo and PWM on pins 9 and 10 lose Timer1. The library
  touches no timer unless you call it.
- `nav.status()`: `AccelNav::REFUSED` (the last input hit a rail), `SATURATED`, `MISSED`, `DROPPED`.
- Telemetry: `nav.begin(Serial, AccelNav::TEXT)` prints a line of positions per sample for the Serial
  Monitor and Plotter; `nav.begin(Serial, AccelNav::BINARY)` streams the accelnav frames, which
  `accelnav record PORT --manifest extras/acnframe.json` records. Call `nav.poll()` in every `loop()`.

## Examples

- `AccelnavStream`: Timer1 at the model's rate, binary telemetry at 115200 baud.
- `AccelnavPlotter`: samples on `micros()`, prints positions for the Serial Plotter (115200 baud).

Each builds in the Arduino IDE, with arduino-mk (`make` in its folder) or with PlatformIO (`pio run` in
its folder: `platformio.ini`).

## Names

Every global symbol and header of the library starts with `acn`, `accelnav` or `AccelNav`, so it links
beside other libraries.
"""


def _license() -> str:
    return (firmware_dir() / "boards" / "arduino" / "LICENSE").read_text()


def _keywords() -> str:
    rows = [("AccelNav", "KEYWORD1")]
    rows += [(m, "KEYWORD2") for m in ("begin", "update", "missed", "due", "tick", "poll", "startTimer1",
                                        "position", "velocity", "acceleration", "bias", "status", "samples",
                                        "printPositions")]  # fmt: skip
    rows += [(c, "LITERAL1") for c in ("NONE", "BINARY", "TEXT", "REFUSED", "SATURATED", "MISSED", "DROPPED")]
    return "# Syntax colouring of the AccelNav library (Arduino IDE)\n" + "".join(f"{k}\t{t}\n" for k, t in rows)


def _library_json(model: Model, name: str, sentence: str, maintainer: tuple[str, str | None], url: str) -> str:
    who: dict[str, object] = {"name": maintainer[0], "maintainer": True}
    if maintainer[1]:
        who["email"] = maintainer[1]
    data = {
        "name": name,
        "version": GENERATOR_VERSION,
        "description": sentence,
        "keywords": ["accelerometer", "kalman filter", "position", "fixed point"],
        "homepage": url,
        "authors": [who],
        "license": "MIT",
        "frameworks": ["arduino"],
        "platforms": ["atmelavr"],
        "headers": ["AccelNav.h"],
        "examples": [{"name": e, "base": f"examples/{e}", "files": [f"{e}.ino"]} for e in EXAMPLES],
        "export": {"exclude": ["examples/*/build-*"]},
    }
    return json.dumps(data, indent=2) + "\n"


_MAINTAINER = re.compile(r"([^<>\n\r=]{1,50}?)\s*(?:<([^<>@\s]+@[^<>@\s]+)>)?")
_URL = re.compile(r"https?://[A-Za-z0-9._~:/?#@!$&'()*+,;=%-]{1,240}")


def check_publisher(maintainer: str, url: str) -> tuple[str, str | None]:
    """``maintainer`` ("Name <email>" or "Name") as (name, email) and ``url`` checked: they go into
    library.properties and library.json; ValueError (one line) otherwise."""
    m = _MAINTAINER.fullmatch(maintainer.strip())
    if m is None or not m[1].strip():
        raise ValueError(f"--maintainer: got {ascii(maintainer[:60])}; accepted: 'Name' or 'Name <email>' (50 "
                         "characters, no '<', '>', '=' or line break in the name)")  # fmt: skip
    if not _URL.fullmatch(url):
        raise ValueError(f"--url: got {ascii(url[:60])}; accepted: an http:// or https:// address")
    return m[1].strip(), m[2]


def library(model: Model, form: str | None = None, *, maintainer: str, url: str) -> dict[str, str]:
    """Every file of the model's Arduino library, by its path inside the library folder. ``maintainer``
    and ``url`` (who publishes it, and where a person reads about it) go into its manifests."""
    _refuse(model)
    who = check_publisher(maintainer, url)
    aref, wiring = reference(model)
    gen = generate(model, form=form)
    fw = firmware_dir()
    name = library_name(model)
    n = len(model.axes)
    files = {f"src/{k}": v for k, v in gen.items() if k.endswith((".c", ".h"))}
    files["extras/acnframe.json"] = gen["acnframe.json"]  # the host's decoder: `accelnav record --manifest`
    files["extras/accelnav.json"] = gen["accelnav.json"]
    for src in APP_SOURCES:
        files[f"src/acn_{src}.h"] = _prefixed((fw / "src" / f"{src}.h").read_text(), source=False)
        files[f"src/acn_{src}.c"] = _prefixed((fw / "src" / f"{src}.c").read_text(), source=True)
    files["src/acn_board.h"] = (fw / "boards" / "acn_board.h").read_text()
    files["src/acn_names.h"] = _names_h(model)
    files["src/acn_model.h"] = _model_h(model, aref, wiring)
    for src in ("AccelNav.h", "AccelNav.cpp"):
        files[f"src/{src}"] = (fw / "boards" / "arduino" / src).read_text()
    for ex in EXAMPLES:
        ino = (fw / "boards" / "arduino" / f"{ex}.ino").read_text()
        for key, value in {
            "@MODEL@": model.name,
            "@PINS_DOC@": ", ".join(f"{a.name} on A{i}" for i, a in enumerate(model.axes)),
            "@RATE@": f"{model.rate_hz:g}",
        }.items():
            ino = ino.replace(key, value)
        files[f"examples/{ex}/{ex}.ino"] = ino
        files[f"examples/{ex}/Makefile"] = _makefile(name)
        files[f"examples/{ex}/platformio.ini"] = _platformio_ini(name)
    sentence = f"Position, velocity and bias from an analog accelerometer: model {model.name}."
    files["library.properties"] = "\n".join(
        [
            f"name={name}",
            f"version={GENERATOR_VERSION}",
            "author=accelnav codegen (generated from a model file)",
            f"maintainer={who[0]}" + (f" <{who[1]}>" if who[1] else ""),
            f"sentence={sentence}",
            f"paragraph=A fixed-point Kalman filter per axis ({n} axes at {model.rate_hz:g} Hz) generated from the "
            f"model file (sha256 {model.sha256[:16]}...): AccelNav nav; nav.begin(); nav.update(); "
            "nav.position(axis). Telemetry for the Serial Plotter or the accelnav recorder. Regenerate, do not edit.",
            "category=Sensors",
            f"url={url}",
            "architectures=avr",
            "includes=AccelNav.h",
            "",
        ]
    )
    files["library.json"] = _library_json(model, name, sentence, who, url)
    files["README.md"] = _readme(model, name, wiring)
    files["LICENSE"] = _license()
    files["keywords.txt"] = _keywords()
    return files


ARDUINO_DIR = "/usr/share/arduino"  # Debian's arduino-core-avr and arduino-mk (the examples' Makefile says so too)
BOARDS = ("uno",)
SKETCH_TIMEOUT_S = 600


def _board_limits(board: str) -> tuple[int, int] | None:
    """(upload.maximum_size, upload.maximum_data_size) of ``board`` in the core's boards.txt: the flash
    beside the bootloader and the RAM the IDE allows; None without the core."""
    from pathlib import Path

    boards = Path(ARDUINO_DIR, "hardware", "arduino", "avr", "boards.txt")
    if not boards.is_file():
        return None
    text = boards.read_text()
    got = [re.search(rf"^{board}\.upload\.{k}=(\d+)\s*$", text, re.M) for k in ("maximum_size", "maximum_data_size")]
    return (int(got[0][1]), int(got[1][1])) if all(got) else None


def sketch_fit(files: dict[str, str], name: str, board: str) -> tuple[list[str], str | None]:
    """Every example sketch of the library ``files`` built for ``board`` with arduino-mk (the core, the
    library, LTO and avr-libc as a user's build links them) and sized: (report lines, a one-line
    refusal or None). Without arduino-mk or the core the lines say so and nothing is refused."""
    import shutil
    import subprocess
    import tempfile
    from pathlib import Path

    from .targets import image_size, missing_tools, part

    if board not in BOARDS:
        raise ValueError(f"--board: got {ascii(board[:40])}; accepted: {', '.join(BOARDS)} (or none: no link)")
    limits = _board_limits(board)
    p = part("atmega328p")
    if missing_tools(p):
        return [f"board {board}: {missing_tools(p)}: the sketches not linked, no verdict"], None
    if limits is None or shutil.which("make") is None or not Path(ARDUINO_DIR, "Arduino.mk").is_file():
        return [f"board {board}: arduino-mk or arduino-core-avr not found: the sketches not linked, no verdict"], None
    flash_max, ram_max = limits
    lines = [f"board {board}: {flash_max} B flash beside the bootloader, {ram_max} B RAM less {p.stack} B stack "
             "(the firmware's, measured); each example sketch linked with arduino-mk:"]  # fmt: skip
    refusal = None
    with tempfile.TemporaryDirectory(prefix="accelnav-sketch-") as tmp:
        root = Path(tmp, name)
        for path, text in files.items():
            (root / path).parent.mkdir(parents=True, exist_ok=True)
            (root / path).write_text(text)
        for ex in EXAMPLES:
            folder = root / "examples" / ex
            try:
                lift = "ACN_LDFLAGS=-Wl,--defsym=__TEXT_REGION_LENGTH__=0x40000"
                done = subprocess.run(["make", "-s", lift], cwd=folder, capture_output=True, text=True,
                                      timeout=SKETCH_TIMEOUT_S)  # fmt: skip
            except subprocess.TimeoutExpired:
                raise ValueError(f"--board {board}: {ex} did not build within {SKETCH_TIMEOUT_S} s") from None
            elves = sorted(folder.glob("build-*/*.elf"))
            if done.returncode or not elves:
                why = [ln for ln in done.stderr.splitlines() if "error" in ln.lower()] or done.stderr.splitlines()
                raise ValueError(f"--board {board}: {ex} did not build: " + (why or ["failed"])[0][:300])
            flash, ram = image_size(p, elves[0])
            ok = flash <= flash_max and ram + p.stack <= ram_max
            lines.append(f"  {ex:<16} flash {flash} B, RAM {ram} B: {'fits' if ok else 'does not fit'}")
            if not ok and refusal is None:
                need = [f"{flash} B flash of {flash_max}"] if flash > flash_max else []
                need += [f"{ram} B RAM + {p.stack} B stack of {ram_max}"] if ram + p.stack > ram_max else []
                refusal = f"--board {board}: the {ex} sketch does not fit: needs {' and '.join(need)} (linked)"
    return lines, refusal
