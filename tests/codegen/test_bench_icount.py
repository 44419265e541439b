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
    _no_overflow(res)
    # SysTick ticks on the core clock and icount runs one instruction per ns: 25 MHz and 16 MHz
    ipt = {core: f"{c.instructions_per_tick:.2f}" for core, c in res.items()}
    assert ipt == {"M3": "40.00", "M0": "62.50"}, ipt
    for tag in ("cov", "gs"):
        m3, m0 = res["M3"].per_step[tag], res["M0"].per_step[tag]
        # ARMv6-M has no 32x32->64 multiply: the M0 needs more instructions for the same step
        assert m0 > m3 > 20, (tag, m3, m0)


# Issue #12's step and RAM targets (gain schedule <= 80 instructions per axis-step on the M3, <= 64 B of
# RAM per axis) are targets, not behaviour: bench/speed/bench_codegen_icount.py prints them (goal,
# measured, met) in make bench's targets table. What is asserted here holds whatever the figures: the
# step runs without saturating on either core.


def test_gain_schedule_runs_without_overflow_at_1khz(tmp_path):
    _no_overflow(_counts(1000.0, tmp_path))


def _no_overflow(res) -> None:
    assert res["M3"].per_step["gs"] > 20 and res["M0"].ram["gs"] > 0
    assert res["M3"].overflow == 0 and res["M0"].overflow == 0
