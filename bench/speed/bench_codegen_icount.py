"""Instructions per axis-step of the generated filters on an emulated Cortex-M3 and Cortex-M0.

Builds the fixed-point covariance form, the fixed-point gain-schedule form and
the float32 variant (soft float) of one model from the same generator, twice:
for the Cortex-M3, linked with the mps2-an385 runtime (firmware/boards/mps2_an385)
and run under `qemu-system-arm -M mps2-an385 -icount shift=0 -semihosting`, and
for the Cortex-M0 (no 32x32->64 multiply: 64-bit products go through libgcc),
linked with the microbit runtime (firmware/boards/microbit) and run under
`-M microbit` the same way. With icount every instruction is 1 ns of virtual
time and SysTick ticks on the core clock (25 MHz: 40 instructions per tick;
16 MHz: 62.5); a loop of a known 2,000,000 instructions checks that ratio on
each run. Each filter runs over N simulated samples (ADC codes, input
conversion included) and the count is averaged per step. The loop and call
overhead is measured with an empty function of the same signature and
reported separately. Flash and RAM come from arm-none-eabi-size and the state
struct.

    .venv/bin/python bench/speed/bench_codegen_icount.py [MODEL.toml] [--rate HZ] [--samples N] [--scenario NAME]

The scenario has no clipped sample: the figures are those of the common path (the gain-schedule
form follows a skipped sample out of line, codegen.follow). Previous figures (issue #4's closing
note, same bench, 100 Hz default model): covariance 333.0, gain schedule 89.6, float32 3007.1
instructions per step; RAM 72 / 64 / 52 B per axis; flash 2260 / 9852 B per axis. Issue #12 (main's
generator in its own venv, same run): covariance 333.0 -> 296.0 at 100 Hz, 332.0 -> 295.0 at 1 kHz;
RAM 64 B per axis both; flash 2250 -> 2084 B per axis at 100 Hz (the reciprocal's 256 B table
included, shared by the axes). Gain schedule after issue #12 (following skips; its gain formats hold
the gains after a gap): 94.5 instructions per step at 100 Hz (89.5 before, same run), 106.8 at 1 kHz
(98.7); RAM 96 B per axis (64); flash 13648 B per axis at 100 Hz (9852), 27622 B at 1 kHz (13904).
Gain schedule's step after issue #12's step work (k's sign bit as the follow flag, eps carried as
eps - eps_bar, v and Ts^2 a in the SMLAL accumulators; same run, main before it): 78.6 at 100 Hz
(94.5), 84.2 at 1 kHz (106.8); RAM 88 B per axis (96).
Gain-schedule table, issue #12 (main c6b42e5 measured at the start of the same session -> this
generator): 100 Hz 94.5 -> 94.2 instructions per step, flash 13648 -> 9440 B per axis, of which table
8424 -> 4272 B (axis x; y 4440); 1 kHz 106.8 -> 105.6, flash 27622 -> 14490 B, table 26328 -> 9912 B
(y 8856); RAM 96 B both. The 2 KB table target is not met.
Gain schedule at 1 kHz, Ts^2/2 a onto v before v's shift (main 0b32d51 -> this generator, same run):
82.8 -> 78.8 instructions per step, flash 14448 -> 14426 B per axis; 100 Hz unchanged (78.3, 9398 B);
RAM 88 B both.
Covariance form with c_e in a fine format away from gaps (issue #12's margin; main 0b32d51 in its own
venv, same run): 298.0 -> 298.2 at 100 Hz, 298.0 -> 298.9 at 1 kHz (the first ~40 samples, until c_e
settles, take the out-of-line path); RAM 64 B per axis both; flash 3384 -> 3436 B per axis at 100 Hz.
Gain schedule after the follow fix (the deviation's zoom z added to the state, K_a read from the
schedule's row instead of a state copy so that the state stays 88 B; main 2ef5af7 in the same session):
79.3 instructions per step at 100 Hz (78.3), 79.6 at 1 kHz (78.7); RAM 88 B per axis (88).
Checkpoint images for the compact telemetry (accelnav_AXIS_save / _load, both forms; main 2ef5af7 in
its own venv, same session): instructions per step unchanged, gain schedule 78.3 / 78.7 and covariance
298.2 / 298.9 at 100 Hz / 1 kHz; RAM unchanged; flash per axis at 100 Hz (this bench's -O2 object, load
included, which the firmware's --gc-sections drops) 3436 -> 3580 B covariance, 9398 -> 9636 B gain
schedule on the M3, 5534 -> 6282 and 12616 -> 13744 B on the M0.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from accelnav.hil_sim.targets.icount import CORES, counts
from accelnav.model.load import load_model

NAMES = {"cov": "fixed point, covariance form", "gs": "fixed point, gain-schedule form", "f32": "float32 (soft float)"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=None)
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--rate", type=float, default=None, help="override the model's sampling.rate_hz")
    ap.add_argument("--scenario", default="vehicle")
    ap.add_argument("--keep", type=Path, help="keep the build in this directory")
    args = ap.parse_args(argv)
    model = load_model(args.model)
    if args.rate is not None:
        from accelnav.model.load import loads_model

        text = model.text.replace(f"rate_hz = {model.rate_hz!r}", f"rate_hz = {args.rate!r}")
        model = loads_model(text, source=f"{model.source}@{args.rate:g}Hz")
        assert model.rate_hz == args.rate, "rate_hz not found in the model text"
    if model.sensor.kind != "analog":
        raise SystemExit("bench: analog models only for now")
    from accelnav.hil_sim.sim.sensor import simulate

    run = simulate(model, args.scenario, args.samples / model.rate_hz, seed=1)
    codes = run.code[: args.samples, 0]
    res = counts(model, codes, args.keep or Path(tempfile.mkdtemp(prefix="acn_bench_")))
    m3, m0 = res["M3"], res["M0"]
    print(
        f"model {model.name} ({model.sha256[:12]}), {model.rate_hz:g} Hz, scenario {args.scenario}, {m3.steps} steps,"
    )
    print("arm-none-eabi-gcc -O2, qemu-system-arm -icount shift=0: Cortex-M3 on mps2-an385, Cortex-M0 on microbit")
    for core, c in res.items():
        print(
            f"{core}: {c.instructions_per_tick:.2f} instructions per tick; loop + call overhead (empty step) "
            f"{c.empty:.1f} per step"
        )
    print(
        f"{'variant':<34} {'M3 insn':>8} {'net':>8} {'M0 insn':>8} {'net':>8} {'M0/M3':>6}"
        f" {'flash M3':>8} {'flash M0':>8} {'RAM B':>6}"
    )
    for tag in NAMES:
        row = f"{NAMES[tag]:<34}"
        for c in res.values():
            row += f" {c.per_step[tag]:8.1f} {c.net[tag]:8.1f}"
        row += f" {m0.per_step[tag] / m3.per_step[tag]:6.2f}"
        row += "".join(f" {res[core].flash_per_axis[tag]:8d}" for core in CORES)
        print(row + f" {m0.ram[tag]:6d}")
    print(f"flash is per axis (object size / {len(model.axes)} axes; libgcc routines not included)")
    table = m3.table_bytes
    print(f"gain-schedule table (in its flash): {', '.join(str(b) for b in table)} B per axis")
    per = m3.per_step
    f32 = per["f32"]
    print(f"M3: float32 / gain-schedule: {f32 / per['gs']:.1f}x;  float32 / covariance: {f32 / per['cov']:.1f}x")
    print("overflow counters: " + ", ".join(f"{core} {c.overflow}" for core, c in res.items()))
    rate = f"{model.rate_hz:g} Hz"
    print()
    print("| target | goal | measured | met |")
    print("|---|---|---|---|")
    rows = [
        (f"M3 covariance step, {rate}", "<= 300 instructions", per["cov"], per["cov"] <= 300),
        (f"M3 gain-schedule step, {rate}", "<= 80 instructions", per["gs"], per["gs"] <= 80),
        (f"M3 float32 over gain schedule, {rate}", ">= 12x", per["f32"] / per["gs"], per["f32"] >= 12 * per["gs"]),
        (f"covariance RAM per axis, {rate}", "<= 64 B", m3.ram["cov"], m3.ram["cov"] <= 64),
        (f"gain-schedule RAM per axis, {rate}", "<= 64 B", m3.ram["gs"], m3.ram["gs"] <= 64),
    ]
    rows += [(f"gain-schedule table, axis {i}, {rate}", "<= 2048 B", b, b <= 2048) for i, b in enumerate(table)]
    for what, goal, value, met in rows:
        print(f"| {what} | {goal} | {f'{value:.1f}'.removesuffix('.0')} | {'yes' if met else 'no'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
