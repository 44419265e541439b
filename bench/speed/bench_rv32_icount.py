"""Instructions per 2-axis sample of the generated filters on an RV32IMAC (QEMU sifive_e) beside the
Cortex-M3 (QEMU mps2-an385), from the same run.

Both filter forms (fixed-point covariance, fixed-point gain schedule) of one model are generated
once and built twice at -O2: arm-none-eabi-gcc -mcpu=cortex-m3 -mthumb with the mps2_an385 runtime,
and riscv64-unknown-elf-gcc -march=rv32imac -mabi=ilp32 with the sifive_e runtime (the firmware
boards' own runtimes, firmware/boards). The driver steps every axis on each simulated sample (ADC
codes, input conversion included) and counts, with QEMU's -icount shift=0, the instructions of the
whole run: on the M3 SysTick ticks (40 instructions per tick at 25 MHz), on RV32 the mcycle CSR
(one per instruction under icount); a loop of exactly 2 000 000 instructions checks each count.
The loop and call overhead (an empty step per axis) is reported separately. Each core also prints
an FNV-1a hash of every axis' final state struct: equal hashes mean the two cores computed the same
bits. Flash is the filter object's text + data (riscv64-unknown-elf-size, arm-none-eabi-size).

    .venv/bin/python bench/speed/bench_rv32_icount.py [MODEL.toml] [--samples N] [--scenario NAME]

Issue 26's figures (default model, 100 Hz, vehicle, 2000 samples; arm-none-eabi-gcc and
riscv64-unknown-elf-gcc 12.2, QEMU 7.2), instructions per 2-axis sample, M3 -> RV32 in the same
run: covariance 594.4 -> 1212.9 (2.04x), gain schedule 157.5 -> 300.4 (1.91x); flash of the
filter object 7160 -> 13274 B and 21172 -> 29044 B; final states bit-identical. RV32IMAC has no
32x32->64 multiply-accumulate (SMLAL: mul + mulh + two adds and a carry via sltu) and no carry
flag for the 64-bit adds and shifts of the Q formats.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from accelnav.hil_sim.targets.icount_sample import CORES, FORMS, driver, run_core
from accelnav.model.load import load_model


# core -> compiler, flags, runtime folder, linker script, link flags, size tool, qemu machine and binary
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", nargs="?", default=None)
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--scenario", default="vehicle")
    ap.add_argument("--keep", type=Path, help="keep the builds in this folder")
    args = ap.parse_args(argv)
    model = load_model(args.model)
    if model.sensor.kind != "analog":
        raise SystemExit("bench: analog models only for now")
    from accelnav.hil_sim.sim.sensor import simulate

    run = simulate(model, args.scenario, args.samples / model.rate_hz, seed=1)
    main_c = driver(model, run.code[: args.samples])
    tmp = args.keep or Path(tempfile.mkdtemp(prefix="acn_bench_rv32_"))
    res = {core: run_core(core, model, main_c, tmp / core) for core in CORES}
    n, nax = res["M3"][0]["n"], len(model.axes)
    print(f"model {model.name} ({model.sha256[:12]}), {model.rate_hz:g} Hz, scenario {args.scenario}, {n} samples,")
    print(f"{nax} axes stepped per sample, -O2, -icount shift=0: Cortex-M3 on mps2-an385, RV32IMAC on sifive_e")
    for core, (vals, _) in res.items():
        empty = vals["empty"] / n
        print(
            f"{core}: calibration loop {vals['calib_2M']} of 2000000 instructions; loop + calls {empty:.1f} per sample"
        )
    print("| form | M3 insn / sample | RV32 insn / sample | RV32 / M3 | M3 flash B | RV32 flash B |")
    print("|---|---:|---:|---:|---:|---:|")
    names = dict(FORMS)
    for tag, _ in FORMS:
        per = {core: res[core][0][tag] / n for core in CORES}
        flash = {core: res[core][1][tag] for core in CORES}
        print(
            f"| {names[tag]} | {per['M3']:.1f} | {per['RV32']:.1f} | {per['RV32'] / per['M3']:.2f} "
            f"| {flash['M3']} | {flash['RV32']} |"
        )
    print(f"instructions per {nax}-axis sample include the loop and call overhead above; flash: the filter object")
    same = all(res["M3"][0][f"hash_{t}"] == res["RV32"][0][f"hash_{t}"] for t, _ in FORMS)
    print(f"final states, M3 vs RV32: {'bit-identical' if same else 'DIFFERENT'}")
    print("overflow counters: " + ", ".join(f"{core} {res[core][0]['overflow']}" for core in CORES))
    return 0


if __name__ == "__main__":
    sys.exit(main())
