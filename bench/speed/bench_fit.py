"""Does the fit check state what the linker makes? One table from one run, ATmega328P (Uno).

For 1-, 2- and 3-axis models (the shipped default's axes, a third with its own bias constants, as
fit-bias writes them), covariance form:

* before: the filter's object alone (codegen.targets.measure, what `--report --target` read until
  issue 34: code the linker drops counted, the application, libc and libgcc's helpers not);
* after: the firmware image `--report --target atmega328p` now links (codegen.targets.link);
* real: the image the PIL runs build (hil_sim's firmware build, its own size check when too big).

Goal: the stated flash within 2 % of the real link. Then the two example sketches of
`codegen --arduino` on the 2- and 3-axis models read by a 10-bit ADC, linked with arduino-mk as a user builds
them, against the Uno's 32256 B beside the bootloader.

    .venv/bin/python bench/speed/bench_fit.py
"""

from __future__ import annotations

import re
import sys
import tempfile
from pathlib import Path

from accelnav.codegen import arduino, targets
from accelnav.codegen.generated import generate
from accelnav.hil_sim.targets.firmware import FirmwareError, firmware_images
from accelnav.model.load import load_model
from accelnav.resources import models_dir

THIRD = '[[axes]]\nname = "z"\nc1 = 0.03\nc2 = -0.07\nT = 410.0\nzero_g_v = 2.497\n\n'


def models(tmp: Path) -> dict[int, Path]:
    """1, 2, 3 axes: the default's x, x and y, x y and z."""
    text = (models_dir() / "adxl250_default.toml").read_text()
    head, *axes = re.split(r"(?=^\[\[axes\]\])", text, flags=re.M)
    y, tail = re.split(r"(?=^\[noise\])", axes[1], flags=re.M)
    out = {}
    for n, body in ((1, axes[0]), (2, axes[0] + y), (3, axes[0] + y + THIRD)):
        path = tmp / f"axes{n}.toml"
        path.write_text(head + body + tail)
        out[n] = path
    return out


def real(p: targets.Part, path: Path, tmp: Path) -> int:
    try:
        images = firmware_images(p.key, str(path))
    except FirmwareError as e:
        return int(re.search(r"needs (\d+) B flash", str(e))[1])
    elf = tmp / "real.elf"
    elf.write_bytes(images["accelnav_fw.elf"])
    return targets.image_size(p, elf)[0]


def main() -> int:
    p = targets.part("atmega328p")
    if targets.missing_tools(p):
        print(targets.missing_tools(p))
        return 1
    print(f"{'model':<8} {'before B':>9} {'after B':>8} {'real B':>7}  {'goal':<16} {'measured':<22} met")
    with tempfile.TemporaryDirectory() as tmp:
        for n, path in models(Path(tmp)).items():
            model = load_model(path)
            files = generate(model, form="covariance")
            before = targets.measure(p, files, "accelnav", "covariance").flash
            after = targets.link(p, files, "covariance").flash
            ref = real(p, path, Path(tmp))
            dev, old = abs(after - ref) / ref, abs(before - ref) / ref
            met = "yes" if dev <= 0.02 else "NO"
            print(f"{n} axes   {before:9d} {after:8d} {ref:7d}  {'|after-real| <= 2%':<16} "
                  f"{dev:6.2%} (before {old:6.2%})  {met}")  # fmt: skip
        for n in (2, 3):  # the goal: a 3-axis fitted model's sketch fits an Uno with its bootloader
            uno = Path(tmp, f"uno{n}.toml")
            uno.write_text(models(Path(tmp))[n].read_text().replace("adc_bits = 12", "adc_bits = 10"))
            files = arduino.library(load_model(uno), maintainer="bench", url="https://example.org")
            try:
                lines, refusal = arduino.sketch_fit(files, arduino.library_name(load_model(uno)), "uno")
            except ValueError as e:
                print(f"sketches, {n} axes: {e}")
                return 1
            print(f"sketches, {n} axes:")
            print("\n".join(lines))
            verdict = refusal or "both sketches fit the Uno beside its bootloader"
            print(f"{n} axes: {verdict}  met: {'NO' if refusal else 'yes'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
