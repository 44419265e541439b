"""Instruction counts per step on both emulated cores: Cortex-M3 (mps2-an385) and Cortex-M0 (microbit),
each checked against a loop of known length, for both filter forms (accelnav.hil_sim.targets.icount, the
function bench/speed/bench_codegen_icount.py prints)."""

from __future__ import annotations

import os
import shutil

import pytest

from accelnav.model.load import load_model, loads_model


def _counts(rate: float, workdir):
    """icount.counts on 2000 vehicle samples at ``rate``; skips (fails under ACCELNAV_REQUIRE_PIL=1) without tools."""
    if shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None:
        reason = "needs qemu-system-arm and arm-none-eabi-gcc (Debian: qemu-system-arm gcc-arm-none-eabi)"
        if os.environ.get("ACCELNAV_REQUIRE_PIL") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_PIL=1 but it {reason}")
        pytest.skip(reason)
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.hil_sim.targets.icount import counts

    model = load_model()
    if rate != model.rate_hz:
        text = model.text.replace(f"rate_hz = {model.rate_hz!r}", f"rate_hz = {rate!r}")
        model = loads_model(text, source=f"{model.source}@{rate:g}Hz")
        assert model.rate_hz == rate
    run = simulate(model, "vehicle", 2000 / model.rate_hz, seed=1)
    return counts(model, run.code[:2000, 0], workdir)


def test_bench_counts_instructions_per_step_on_m0_and_m3(tmp_path):
    res = _counts(100.0, tmp_path)
    _gain_schedule_within_targets(res, 100.0)  # the 100 Hz step and RAM targets from the same run
    # SysTick ticks on the core clock and icount runs one instruction per ns: 25 MHz and 16 MHz
    ipt = {core: f"{c.instructions_per_tick:.2f}" for core, c in res.items()}
    assert ipt == {"M3": "40.00", "M0": "62.50"}, ipt
    for tag in ("cov", "gs"):
        m3, m0 = res["M3"].per_step[tag], res["M0"].per_step[tag]
        # ARMv6-M has no 32x32->64 multiply: the M0 needs more instructions for the same step
        assert m0 > m3 > 20, (tag, m3, m0)


# Issue #12's step targets for the gain schedule on the Cortex-M3 (instructions per axis-step, input
# conversion and loop included, as the bench measures them: 2000 steps): <= 80 met at both rates.
# For RAM (88 B per axis, target 64) it is NOT met: a ceiling at today's figure, so that a regression
# fails while the gap stays stated.
GS_STEP_MAX = {100.0: 80.0, 1000.0: 80.0}
GS_RAM_MAX = 88


def test_gain_schedule_step_and_ram_targets_at_1khz(tmp_path):
    _gain_schedule_within_targets(_counts(1000.0, tmp_path), 1000.0)


def _gain_schedule_within_targets(res, rate: float) -> None:
    m3 = res["M3"].per_step["gs"]
    ram = res["M0"].ram["gs"]
    assert m3 <= GS_STEP_MAX[rate], f"{rate:g} Hz: {m3} instructions per step (ceiling {GS_STEP_MAX[rate]})"
    assert ram <= GS_RAM_MAX, f"{ram} B per axis (ceiling {GS_RAM_MAX})"
    assert res["M3"].overflow == 0 and res["M0"].overflow == 0
