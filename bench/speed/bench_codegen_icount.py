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
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from accelnav.codegen.emit_c import emit
from accelnav.codegen.report import struct_size
from accelnav.hil_sim.targets.qemu import run_to_exit
from accelnav.model.load import load_model
from accelnav.resources import firmware_dir

CFLAGS = ["-mthumb", "-masm-syntax-unified", "-O2", "-std=c99", "-ffreestanding", "-Wall", "-Wextra", "-Werror"]
# core -> (gcc -mcpu, runtime folder, linker script, qemu machine)
CORES = {
    "M3": ("cortex-m3", "mps2_an385", "mps2_an385.ld", "mps2-an385"),
    "M0": ("cortex-m0", "microbit", "nrf51822.ld", "microbit"),
}
VARIANTS = (("cov", "covariance", "fixed"), ("gs", "gain_schedule", "fixed"), ("f32", "covariance", "float32"))

MAIN = r"""
#include "board.h"
#include "accelnav_cov.h"
#include "accelnav_gs.h"
#include "accelnav_f32.h"

static const int32_t codes[] = {CODES};
#define N (sizeof codes / sizeof codes[0])

__attribute__((noinline)) static bool empty_step(accelnav_cov_AX_t *s, int32_t code)
{
    __asm__ volatile("" ::"r"(s), "r"(code) : "memory");
    return code > 0;
}

static void report(const char *name, uint32_t ticks)
{
    board_puts(name);
    board_puts(" ");
    board_put_u32(ticks);
    board_puts("\n");
}

/* a loop of exactly 2 instructions per iteration (subs, bne): checks 40 instructions per tick */
__attribute__((noinline)) static void known_loop(uint32_t n)
{
    __asm__ volatile("1: subs %0, %0, #1\n bne 1b\n" : "+r"(n)::"cc");
}

int main(void)
{
    static accelnav_cov_AX_t cov;
    static accelnav_gs_AX_t gs;
    static accelnav_f32_AX_t f32;
    uint32_t k, t0;
    board_ticks_start();
    t0 = board_ticks();
    known_loop(1000000u);
    report("calib_2M", board_ticks_since(t0));
    accelnav_cov_AX_init(&cov);
    t0 = board_ticks();
    for (k = 0; k < N; ++k) {
        empty_step(&cov, codes[k]);
    }
    report("empty", board_ticks_since(t0));
    t0 = board_ticks();
    for (k = 0; k < N; ++k) {
        accelnav_cov_AX_step(&cov, codes[k]);
    }
    report("cov", board_ticks_since(t0));
    accelnav_gs_AX_init(&gs);
    t0 = board_ticks();
    for (k = 0; k < N; ++k) {
        accelnav_gs_AX_step(&gs, codes[k]);
    }
    report("gs", board_ticks_since(t0));
    accelnav_f32_AX_init(&f32);
    t0 = board_ticks();
    for (k = 0; k < N; ++k) {
        accelnav_f32_AX_step(&f32, codes[k]);
    }
    report("f32", board_ticks_since(t0));
    report("n", N);
    report("overflow", cov.overflow + gs.overflow);
    return 0;
}
"""


def run_core(core: str, model, codes, tmp: Path) -> tuple[dict, dict, float]:
    """Build the three variants for ``core`` and run them; returns (tick counts, sizes, instructions per tick)."""
    cpu, board_name, ld, machine = CORES[core]
    board = firmware_dir() / "boards" / board_name
    cflags = [f"-mcpu={cpu}", *CFLAGS]
    ax = model.axes[0].name
    tmp.mkdir(parents=True, exist_ok=True)
    sizes = {}
    for tag, form, arith in VARIANTS:
        files = emit(model, form=form, arith=arith, prefix=f"accelnav_{tag}")
        for name, text in files.items():
            (tmp / name).write_text(text)
        obj = tmp / f"accelnav_{tag}.o"
        subprocess.run(["arm-none-eabi-gcc", *cflags, "-c", str(tmp / f"accelnav_{tag}.c"), "-o", str(obj)], check=True)
        out = subprocess.run(["arm-none-eabi-size", str(obj)], check=True, capture_output=True, text=True).stdout
        text, data, bss = (int(x) for x in out.splitlines()[1].split()[:3])
        ram = struct_size(files[f"accelnav_{tag}.h"], f"accelnav_{tag}_{ax}_t")
        sizes[tag] = (text, data, bss, ram)
        if form == "gain_schedule":  # the schedule's table per axis (codegen.gains), part of the flash above
            man = json.loads(files[f"accelnav_{tag}.json"])
            sizes["table"] = [a["schedule"]["flash_bytes"] for a in man["axes"]]
    main_c = MAIN.replace("CODES", ", ".join(str(int(c)) for c in codes)).replace("_AX_", f"_{ax}_")
    (tmp / "main.c").write_text(main_c)
    elf = tmp / "bench.elf"
    runtime = board.parent / "semihost_rt.c"  # the runtime the emulated boards share
    srcs = [tmp / "main.c", board / "startup.c", runtime] + [tmp / f"accelnav_{t}.c" for t, _, _ in VARIANTS]
    inc = ["-I", str(board), "-I", str(board.parent), "-I", str(tmp)]
    link = ["arm-none-eabi-gcc", *cflags, "-nostdlib", *inc, "-T", str(board / ld)]
    subprocess.run([*link, *map(str, srcs), "-lgcc", "-o", str(elf)], check=True)
    # the one way accelnav runs code on the emulator (hil_sim.qemu), with -icount shift=0
    text_out = run_to_exit(elf, icount=True, timeout=300, machine=machine)
    vals = dict(line.split() for line in text_out.splitlines() if len(line.split()) == 2)
    vals = {k: int(v) for k, v in vals.items()}
    return vals, sizes, 2_000_000 / vals["calib_2M"]


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
    tmp = args.keep or Path(tempfile.mkdtemp(prefix="acn_bench_"))
    results = {core: run_core(core, model, codes, tmp / core) for core in CORES}
    n = results["M3"][0]["n"]
    print(f"model {model.name} ({model.sha256[:12]}), {model.rate_hz:g} Hz, scenario {args.scenario}, {n} steps,")
    print("arm-none-eabi-gcc -O2, qemu-system-arm -icount shift=0: Cortex-M3 on mps2-an385, Cortex-M0 on microbit")
    for core, (vals, _, ipt) in results.items():
        empty = vals["empty"] * ipt / vals["n"]
        print(f"{core}: {ipt:.2f} instructions per tick; loop + call overhead (empty step) {empty:.1f} per step")
    names = {
        "cov": "fixed point, covariance form",
        "gs": "fixed point, gain-schedule form",
        "f32": "float32 (soft float)",
    }
    print(
        f"{'variant':<34} {'M3 insn':>8} {'net':>8} {'M0 insn':>8} {'net':>8} {'M0/M3':>6}"
        f" {'flash M3':>8} {'flash M0':>8} {'RAM B':>6}"
    )
    per = {core: {} for core in CORES}
    for tag in ("cov", "gs", "f32"):
        row = f"{names[tag]:<34}"
        for core, (vals, _, ipt) in results.items():
            tot = vals[tag] * ipt / vals["n"]
            per[core][tag] = tot
            row += f" {tot:8.1f} {tot - vals['empty'] * ipt / vals['n']:8.1f}"
        row += f" {per['M0'][tag] / per['M3'][tag]:6.2f}"
        for core in CORES:
            text, data, _bss, ram = results[core][1][tag]
            row += f" {(text + data) // len(model.axes):8d}"
        print(row + f" {ram:6d}")
    print(f"flash is per axis (object size / {len(model.axes)} axes; libgcc routines not included)")
    table = results["M3"][1]["table"]
    print(f"gain-schedule table (in its flash): {', '.join(str(b) for b in table)} B per axis (target <= 2048)")
    m3 = per["M3"]
    ratio = f"float32 / gain-schedule: {m3['f32'] / m3['gs']:.1f}x;  float32 / covariance: {m3['f32'] / m3['cov']:.1f}x"
    print(f"M3: {ratio}")
    print(
        f"M3 targets: covariance <= 300 ({'met' if m3['cov'] <= 300 else 'NOT met'}), gain schedule <= 80 "
        f"({'met' if m3['gs'] <= 80 else 'NOT met'}), float32 >= 12x gain schedule "
        f"({'met' if m3['f32'] >= 12 * m3['gs'] else 'NOT met'})"
    )
    ram = {tag: results["M3"][1][tag][3] for tag in ("cov", "gs")}
    print(
        "RAM targets (<= 64 B per axis): "
        + ", ".join(f"{names[t].split(', ')[-1]} {ram[t]} B ({'met' if ram[t] <= 64 else 'NOT met'})" for t in ram)
    )
    print("overflow counters: " + ", ".join(f"{core} {results[core][0]['overflow']}" for core in CORES))
    return 0


if __name__ == "__main__":
    sys.exit(main())
