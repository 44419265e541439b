"""An Arduino library of a model: ``accelnav codegen MODEL --arduino DIR``.

:func:`library` returns ``{path in the library folder: text}`` in Arduino's layout (1.5 format):
``library.properties``; ``src/`` with the generated filter (accelnav.*), the frame code (acnframe.*),
the firmware's board-independent application (firmware/src: compact telemetry, commands, framing)
and its Arduino board layer (firmware/boards/arduino/acn_arduino.*); ``examples/NAME/NAME.ino``, a
sketch that reads every axis with analogRead at the model's rate from Timer1, runs the filter and
streams the telemetry, with a Makefile for arduino-mk beside it. The host reads that stream as any
board's (``acnframe.json`` sits beside the library's sources). Only the CLI writes files.

The sketch reads 10-bit codes (analogRead), on pins A0, A1, ... in axis order: a model whose input is
not a 10-bit ADC is refused in one line (ModelError), as the Uno has six analog pins.
"""

from __future__ import annotations

from accelnav.model.load import Model, ModelError, c_identifier_from
from accelnav.resources import firmware_dir

from .generated import generate

EXAMPLE = "AccelnavStream"
ANALOG_PINS = 6  # A0..A5 on an Uno
APP_SOURCES = ("app.c", "app.h", "filter_adapter.c", "filter_adapter.h", "link.c", "link.h", "cobs.c", "cobs.h",
               "crc32.c", "crc32.h")  # fmt: skip


def library_name(model: Model) -> str:
    """The library's name, which is also its folder's and what a Makefile's ARDUINO_LIBS names: the model's name
    (which may hold spaces, ':', '=', ...) through the C-identifier rule."""
    return c_identifier_from(model.name, "accelnav_")


def library(model: Model, form: str | None = None) -> dict[str, str]:
    """Every file of the model's Arduino library, by its path inside the library folder."""
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
    gen = generate(model, form=form)
    fw = firmware_dir()
    name = library_name(model)
    files = {f"src/{k}": v for k, v in gen.items() if k.endswith((".c", ".h"))}
    files["acnframe.json"] = gen["acnframe.json"]  # the host's decoder: `accelnav record --manifest`
    files["accelnav.json"] = gen["accelnav.json"]
    for src in APP_SOURCES:
        files[f"src/{src}"] = (fw / "src" / src).read_text()
    files["src/acn_board.h"] = (fw / "boards" / "acn_board.h").read_text()
    for src in ("acn_arduino.h", "acn_arduino.cpp"):
        files[f"src/{src}"] = (fw / "boards" / "arduino" / src).read_text()
    pins = [f"A{i}" for i in range(n)]
    ino = (fw / "boards" / "arduino" / "example.ino").read_text()
    for key, value in {
        "@NAME@": EXAMPLE,
        "@MODEL@": model.name,
        "@PINS_DOC@": ", ".join(f"{a.name} on {p}" for a, p in zip(model.axes, pins, strict=True)),
        "@PINS@": ", ".join(pins),
        "@RATE@": f"{model.rate_hz:g}",
    }.items():
        ino = ino.replace(key, value)
    files[f"examples/{EXAMPLE}/{EXAMPLE}.ino"] = ino
    files[f"examples/{EXAMPLE}/Makefile"] = (
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
        "include $(ARDUINO_DIR)/Arduino.mk\n"
    )
    files["library.properties"] = "\n".join(
        [
            f"name={name}",
            "version=0.1.0",
            "author=accelnav codegen",
            "maintainer=accelnav codegen",
            f"sentence=Position, velocity and acceleration from an analog accelerometer: model {model.name}.",
            f"paragraph=A fixed-point Kalman filter per axis ({n} axes at {model.rate_hz:g} Hz), generated from the "
            f"model file (sha256 {model.sha256[:16]}...), with the accelnav telemetry protocol. Do not edit: "
            "regenerate with accelnav codegen MODEL --arduino DIR.",
            "category=Sensors",
            "url=",
            "architectures=avr",
            "includes=acn_arduino.h",
            "",
        ]
    )
    return files
