"""The codegen instruction-count bench runs on both emulated cores: Cortex-M3 (mps2-an385) and
Cortex-M0 (microbit), each checked against a loop of known length, for both filter forms."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil

import pytest
from conftest import REPO


def _bench():
    """bench/speed/bench_codegen_icount.py as a module; skips (fails under ACCELNAV_REQUIRE_PIL=1) without the tools."""
    if shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None:
        reason = "needs qemu-system-arm and arm-none-eabi-gcc (Debian: qemu-system-arm gcc-arm-none-eabi)"
        if os.environ.get("ACCELNAV_REQUIRE_PIL") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_PIL=1 but it {reason}")
        pytest.skip(reason)
    spec = importlib.util.spec_from_file_location(
        "bench_codegen_icount", REPO / "bench" / "speed" / "bench_codegen_icount.py"
    )
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def test_bench_counts_instructions_per_step_on_m0_and_m3(tmp_path, capsys):
    bench = _bench()
    assert bench.main(["--keep", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    _gain_schedule_within_targets(out, 100.0)  # the 100 Hz step and RAM targets from the same run
    # SysTick ticks on the core clock and icount runs one instruction per ns: 25 MHz and 16 MHz
    assert "M3: 40.00 instructions per tick" in out and "M0: 62.50 instructions per tick" in out
    rows = {}
    for name in ("covariance form", "gain-schedule form"):
        line = next(line for line in out.splitlines() if name in line)
        m3, _, m0, _, ratio = (float(x) for x in re.findall(r"\d+\.\d+", line)[:5])
        rows[name] = (m3, m0, ratio)
    for name, (m3, m0, ratio) in rows.items():
        # ARMv6-M has no 32x32->64 multiply: the M0 needs more instructions for the same step
        assert m0 > m3 > 20, (name, m3, m0)
        assert ratio == pytest.approx(m0 / m3, abs=0.01)
    assert "overflow counters: M3 0, M0 0" in out


# Issue #12's step targets for the gain schedule on the Cortex-M3 (instructions per axis-step, input
# conversion and loop included, as the bench measures them: 2000 steps): <= 80 met at both rates.
# For RAM (88 B per axis, target 64) it is NOT met: a ceiling at today's figure, so that a regression
# fails while the gap stays stated.
GS_STEP_MAX = {100.0: 80.0, 1000.0: 80.0}
GS_RAM_MAX = 88


def test_gain_schedule_step_and_ram_targets_at_1khz(tmp_path, capsys):
    bench = _bench()
    assert bench.main(["--rate", "1000", "--keep", str(tmp_path)]) == 0
    _gain_schedule_within_targets(capsys.readouterr().out, 1000.0)


def _gain_schedule_within_targets(out: str, rate: float) -> None:
    line = next(line for line in out.splitlines() if "gain-schedule form" in line)
    m3 = float(re.findall(r"\d+\.\d+", line)[0])
    ram = int(line.split()[-1])
    assert m3 <= GS_STEP_MAX[rate], f"{rate:g} Hz: {m3} instructions per step (ceiling {GS_STEP_MAX[rate]})"
    assert ram <= GS_RAM_MAX, f"{ram} B per axis (ceiling {GS_RAM_MAX})"
    assert "overflow counters: M3 0, M0 0" in out
