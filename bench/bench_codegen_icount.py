"""Instructions per axis-step of the generated filters on an emulated Cortex-M3, in one run.

Builds the fixed-point covariance form, the fixed-point gain-schedule form and
the float32 variant (soft float) of one model from the same generator, links
them with the mps2-an385 runtime (firmware/boards/mps2_an385) and runs them
under `qemu-system-arm -M mps2-an385 -icount shift=0 -semihosting`. With
icount every instruction is 1 ns of virtual time and SysTick ticks on the
25 MHz core clock, so one tick is 40 instructions; each filter runs over
N simulated samples (ADC codes, input conversion included) and the count is
averaged per step. The loop and call overhead is measured with an empty
function of the same signature and reported separately. Flash and RAM come
from arm-none-eabi-size and the state struct.

    .venv/bin/python bench/bench_codegen_icount.py [MODEL.toml] [--rate HZ] [--samples N] [--scenario NAME]

The gain-schedule form is refused for users (every input can skip samples, and the schedule does not
follow skips: codegen.emit_c.refuse_schedule_with_skips); it is built here with assume_no_skips on a
scenario without clipping, to keep its figures comparable. Previous figures (issue #4's closing
note, same bench, 100 Hz default model): covariance 333.0, gain schedule 89.6, float32 3007.1
instructions per step; RAM 72 / 64 / 52 B per axis; flash 2260 / 9852 B per axis.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from accelnav.codegen.emit_c import emit
from accelnav.codegen.model import load_model
from accelnav.codegen.report import struct_size
from accelnav.codegen.resources import firmware_dir
from accelnav.hil_sim.qemu import run_to_exit

BOARD = firmware_dir() / "boards" / "mps2_an385"
CFLAGS = ["-mcpu=cortex-m3", "-mthumb", "-O2", "-std=c99", "-ffreestanding", "-Wall", "-Wextra", "-Werror"]
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
        from accelnav.codegen.model import loads_model

        text = model.text.replace(f"rate_hz = {model.rate_hz!r}", f"rate_hz = {args.rate!r}")
        model = loads_model(text, source=f"{model.source}@{args.rate:g}Hz")
        assert model.rate_hz == args.rate, "rate_hz not found in the model text"
    if model.sensor.kind != "analog":
        raise SystemExit("bench: analog models only for now")
    from accelnav.hil_sim.sensor import simulate

    run = simulate(model, args.scenario, args.samples / model.rate_hz, seed=1)
    codes = run.code[: args.samples, 0]
    ax = model.axes[0].name
    tmp = args.keep or Path(tempfile.mkdtemp(prefix="acn_bench_"))
    tmp.mkdir(parents=True, exist_ok=True)
    sizes = {}
    for tag, form, arith in VARIANTS:
        files = emit(model, form=form, arith=arith, prefix=f"accelnav_{tag}", assume_no_skips=True)
        for name, text in files.items():
            (tmp / name).write_text(text)
        obj = tmp / f"accelnav_{tag}.o"
        subprocess.run(["arm-none-eabi-gcc", *CFLAGS, "-c", str(tmp / f"accelnav_{tag}.c"), "-o", str(obj)], check=True)
        out = subprocess.run(["arm-none-eabi-size", str(obj)], check=True, capture_output=True, text=True).stdout
        text, data, bss = (int(x) for x in out.splitlines()[1].split()[:3])
        ram = struct_size(files[f"accelnav_{tag}.h"], f"accelnav_{tag}_{ax}_t")
        sizes[tag] = (text, data, bss, ram)
    main_c = MAIN.replace("CODES", ", ".join(str(int(c)) for c in codes)).replace("_AX_", f"_{ax}_")
    (tmp / "main.c").write_text(main_c)
    elf = tmp / "bench.elf"
    srcs = [tmp / "main.c", BOARD / "startup.c"] + [tmp / f"accelnav_{t}.c" for t, _, _ in VARIANTS]
    subprocess.run(
        [
            "arm-none-eabi-gcc",
            *CFLAGS,
            "-nostdlib",
            "-I",
            str(BOARD),
            "-I",
            str(tmp),
            "-T",
            str(BOARD / "mps2_an385.ld"),
            *map(str, srcs),
            "-lgcc",
            "-o",
            str(elf),
        ],
        check=True,
    )
    # the one way accelnav runs code on the emulator (hil_sim.qemu), with -icount shift=0
    text_out = run_to_exit(elf, icount=True, timeout=300)
    vals = dict(line.split() for line in text_out.splitlines() if len(line.split()) == 2)
    vals = {k: int(v) for k, v in vals.items()}
    ipt = 2_000_000 / vals["calib_2M"]
    n = vals["n"]
    empty = vals["empty"] * ipt / n
    print(f"model {model.name} ({model.sha256[:12]}), {model.rate_hz:g} Hz, scenario {args.scenario}, {n} steps,")
    print(f"Cortex-M3 (qemu mps2-an385, -icount shift=0), arm-none-eabi-gcc -O2; {ipt:.2f} instructions per tick")
    print(f"loop + call overhead (empty step): {empty:.1f} instructions per step")
    print(f"{'variant':<34} {'insn/step':>10} {'net':>8} {'flash B':>8} {'RAM B':>6}")
    names = {
        "cov": "fixed point, covariance form",
        "gs": "fixed point, gain-schedule form",
        "f32": "float32 (soft float)",
    }
    per = {}
    for tag in ("cov", "gs", "f32"):
        tot = vals[tag] * ipt / n
        per[tag] = tot
        text, data, bss, ram = sizes[tag]
        flash = (text + data) // len(model.axes)
        print(f"{names[tag]:<34} {tot:10.1f} {tot - empty:8.1f} {flash:8d} {ram:6d}")
    print(f"flash is per axis (object size / {len(model.axes)} axes; libgcc soft-float routines not included)")
    print(
        f"float32 / gain-schedule: {per['f32'] / per['gs']:.1f}x;  float32 / covariance: {per['f32'] / per['cov']:.1f}x"
    )
    print(
        f"targets: covariance <= 300 ({'met' if per['cov'] <= 300 else 'NOT met'}), gain schedule <= 80 "
        f"({'met' if per['gs'] <= 80 else 'NOT met'}), float32 >= 12x gain schedule "
        f"({'met' if per['f32'] >= 12 * per['gs'] else 'NOT met'})"
    )
    print(f"overflow counters: {vals['overflow']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
