"""Instructions per axis-step of the generated filters on emulated Cortex-M3 and Cortex-M0 cores.

:func:`measure` builds the fixed-point covariance form, the fixed-point gain-schedule form and the
float32 variant of one model from the same generator, links them with a counting main() for each core
(mps2-an385's runtime for the M3, microbit's for the M0) and runs it under QEMU with ``-icount shift=0``
(:func:`accelnav.hil_sim.targets.qemu.run_to_exit`), so one instruction is one nanosecond of virtual
time. A loop of a known 2,000,000 instructions checks the instructions-per-tick ratio on each run, and an
empty step of the same signature gives the loop and call overhead. Flash comes from arm-none-eabi-size,
RAM from the state struct. bench/speed/bench_codegen_icount.py prints the figures; the tests assert on
the returned numbers.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from accelnav.codegen.emit_c import emit
from accelnav.codegen.report import struct_size
from accelnav.hil_sim.targets.qemu import run_to_exit
from accelnav.native.cbuild import BOARD_WARN
from accelnav.resources import firmware_dir

CFLAGS = [
    "-mthumb",
    "-masm-syntax-unified",
    "-O2",
    "-std=c99",
    "-ffreestanding",
    *BOARD_WARN,
]


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


@dataclass(frozen=True)
class CoreCounts:
    """One core's run: instructions per axis-step by variant ("cov", "gs", "f32"), total and net of the
    loop and call overhead; flash (text + data) and RAM per axis in bytes; the calibration's ratio."""

    per_step: dict[str, float]
    net: dict[str, float]
    empty: float
    flash_per_axis: dict[str, int]
    ram: dict[str, int]
    table_bytes: list[int]  # the gain schedule's table per axis, part of its flash
    instructions_per_tick: float
    overflow: int
    steps: int


def counts(model, codes, workdir: Path) -> dict[str, CoreCounts]:
    """Every core in :data:`CORES` over the ADC ``codes`` of axis 0, built under ``workdir/<core>``."""
    out = {}
    for core in CORES:
        vals, sizes, ipt = run_core(core, model, np.asarray(codes), Path(workdir) / core)
        n = vals["n"]
        per = {tag: vals[tag] * ipt / n for tag, _, _ in VARIANTS}
        empty = vals["empty"] * ipt / n
        out[core] = CoreCounts(
            per_step=per,
            net={tag: v - empty for tag, v in per.items()},
            empty=empty,
            flash_per_axis={tag: (sizes[tag][0] + sizes[tag][1]) // len(model.axes) for tag, _, _ in VARIANTS},
            ram={tag: sizes[tag][3] for tag, _, _ in VARIANTS},
            table_bytes=list(sizes["table"]),
            instructions_per_tick=ipt,
            overflow=vals["overflow"],
            steps=n,
        )
    return out
