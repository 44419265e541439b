"""The generated filter's constant tables live in flash on AVR, and are read right from there.

On an ATmega a const array is copied into RAM at start unless it is placed in flash (PROGMEM) and
read with pgm_read_*. The covariance form's reciprocal table (256 B) and the gain schedule's rows
(kilobytes) are: the RAM of a build is then the filter's state, and the schedule, too big for the
ATmega328P's flash, runs on an ATmega1284P in simavr bit for bit with the host.

Skipped, with the reason, without avr-gcc / simavr; under ACCELNAV_REQUIRE_AVR=1 (CI) a failure.
"""

from __future__ import annotations

import pytest
from conftest import MODELS

from accelnav.codegen.emit_c import emit
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.targets import simavr
from accelnav.model.load import load_model

SAMPLES = 120


pytestmark = pytest.mark.usefixtures("avr_tools")  # simavr and avr-gcc, or a skip


def _files(name: str, form: str) -> tuple[dict[str, str], object]:
    model = load_model(MODELS / f"{name}.toml")
    files = {k: v for k, v in emit(model, form=form).items() if k.endswith((".c", ".h"))}
    return files, model


@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
def test_filter_ram_is_its_state_alone(tmp_path, form):
    """Static RAM of the generated filter alone (avr-gcc -Os, ATmega328P): the two axes' state structs
    and nothing else: no table copied from flash at start."""
    files, _ = _files("adxl250_default", form)
    _, ram = simavr.object_size(files, tmp_path)
    assert ram == 0, f"{form}: {ram} B of the filter's constants would be copied into RAM"


def test_gain_schedule_from_flash_is_bit_identical_on_an_avr(tmp_path):
    """The gain schedule's rows read with pgm_read_dword on an ATmega1284P (the 328P's flash cannot hold
    them) give the host's bits, sample by sample, skips and a rail included."""
    files, model = _files("adxl250_default", "gain_schedule")
    stim = simulate(model, "stress", SAMPLES / model.rate_hz, 3).code.copy()
    stim[40, 0] = 0  # the low rail: a refused sample, the schedule's skip-following path
    drv = simavr.driver_c("accelnav.h", files["accelnav.h"], stim, duty=False)
    host = simavr.run_host(files, drv, tmp_path / "host")
    avr = simavr.run_avr(files, drv, tmp_path / "avr", mcu="atmega1284p")
    assert len(avr.records) == len(host.records) == SAMPLES * len(model.axes)
    assert avr.records == host.records
    assert host.records[40 * len(model.axes)].endswith("0")  # the rail took the refusal path
    assert avr.ram < 2048, f"{avr.ram} B of RAM for a driver whose filter state is a few hundred bytes"
