"""The generated C gives the same bits on a 16-bit-int AVR (ATmega328P in simavr) as on the host.

Every other target has a 32-bit int, so nothing else can catch an integer builtin, shift, literal
or promotion that assumes one. Each shipped model's covariance filter and a small driver
(accelnav.hil_sim.targets.simavr) are built with avr-gcc -Os -std=c99 -Wall -Wextra -Werror and run
in simavr: 200 samples from init (rails and skips included) and 200 more from a checkpoint taken
100 000 samples into a run at rest, every axis' state image and read() output compared with the
same driver built by the host's cc. A second test puts __builtin_clz back on the 32-bit divisor
and shows the comparison catches it. The gain-schedule form does not fit the part's memory: its
refusal is one line naming what it needs.

Skipped, with the reason, without avr-gcc / simavr; under ACCELNAV_REQUIRE_AVR=1 (CI) a failure.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MODELS

from accelnav.codegen.emit_c import emit
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.targets import simavr
from accelnav.model.load import load_model

SAMPLES = 200  # per phase: from init, then from the late checkpoint
WARM = 100_000  # samples at rest before the second phase's checkpoint


pytestmark = pytest.mark.usefixtures("avr_tools")  # simavr and avr-gcc, or a skip


def _case(name: str, form: str = "covariance"):
    """(model, generated C files, stimulus, duty, refused) with a rail (analog) or a bad capture (duty) in
    it, ``refused`` the (sample, axis) the conversion refuses."""
    model = load_model(MODELS / f"{name}.toml")
    files = {k: v for k, v in emit(model, form=form).items() if k.endswith((".c", ".h"))}
    run = simulate(model, "stress", SAMPLES / model.rate_hz, 3)
    duty = model.sensor.kind == "duty_cycle"
    if duty:
        stim = np.stack([run.t1, run.t2], axis=-1)
        refused = (60, 1)  # no high time
        stim[refused + (0,)] = 0
    else:
        stim = run.code.copy()
        refused = (50, 0)  # the low rail
        stim[refused] = 0
    return model, files, stim, duty, refused


def _driver(files, stim, duty, tmp_path) -> str:
    """The comparison driver, its second phase starting from the host's checkpoint after WARM samples."""
    h = files["accelnav.h"]
    warm = simavr.run_host(files, simavr.driver_c("accelnav.h", h, stim, duty=duty, warm_steps=WARM), tmp_path / "w")
    return simavr.driver_c("accelnav.h", h, stim, duty=duty, warm=[bytes.fromhex(r[1:]) for r in warm.records])


def _first_difference(a: list[str], b: list[str]) -> str:
    if len(a) != len(b):
        return f"{len(a)} records against {len(b)}"
    bad = [i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y]
    return f"{len(bad)} of {len(a)} records differ, the first #{bad[0]}: {a[bad[0]][:40]}... vs {b[bad[0]][:40]}..."


@pytest.mark.parametrize("name", ["adxl250_default", "adxl202_duty"])
def test_covariance_filter_is_bit_identical_on_avr(name, tmp_path):
    model, files, stim, duty, refused = _case(name)
    drv = _driver(files, stim, duty, tmp_path)
    host = simavr.run_host(files, drv, tmp_path / "host")
    assert len(host.records) == 2 * SAMPLES * len(model.axes)
    k, i = refused
    assert host.records[k * len(model.axes) + i].endswith("0")  # the refused sample took the refusal path
    # the plain C count of leading zeros (any compiler, any int width) gives the builtin's bits
    plain = simavr.run_host(files, drv, tmp_path / "plain", cflags=["-DACN_PLAIN_CLZ"])
    assert plain.records == host.records, _first_difference(plain.records, host.records)
    avr = simavr.run_avr(files, drv, tmp_path / "avr")
    assert avr.records == host.records, _first_difference(avr.records, host.records)
    assert [n for _, _, n in avr.phases] == [SAMPLES, SAMPLES]
    assert all(0 < top < total for total, top, _ in avr.phases)  # the timer ran: the cycle counts are live


def test_builtin_clz_on_a_uint32_is_caught_on_avr(tmp_path):
    """The hazard this suite is for: __builtin_clz counts in an unsigned int, 16 bits on AVR."""
    _, files, stim, duty, _ = _case("adxl250_default")
    drv = _driver(files, stim, duty, tmp_path)
    host = simavr.run_host(files, drv, tmp_path / "host")
    c = files["accelnav.c"]
    assert c.count("*n = acn_clz32(d);") == 2  # acn_recip and acn_recip_t
    bad = dict(files, **{"accelnav.c": c.replace("*n = acn_clz32(d);", "*n = __builtin_clz(d);")})
    # on the host (32-bit int) the mutation changes nothing ...
    assert simavr.run_host(bad, drv, tmp_path / "bad_host").records == host.records
    # ... on the AVR it changes the filter's state
    avr = simavr.run_avr(bad, drv, tmp_path / "bad_avr")
    assert len(avr.records) == len(host.records)
    assert avr.records != host.records


def test_gain_schedule_refused_in_one_line_naming_the_flash(tmp_path):
    _, files, stim, duty, _ = _case("adxl250_default", "gain_schedule")
    drv = simavr.driver_c("accelnav.h", files["accelnav.h"], stim, duty=duty)
    with pytest.raises(simavr.AvrError) as e:
        simavr.build_avr(files, drv, tmp_path)
    msg = str(e.value)
    assert "\n" not in msg
    need = int(msg.split("needs ")[1].split(" B flash")[0])
    assert need > simavr.FLASH_BYTES, msg
