"""Instructions per sample, every axis stepped, of both fixed-point forms on any emulated core.

:func:`driver` writes a C main() that steps every axis of one model on each of the given ADC samples,
for the covariance and the gain-schedule form, and prints the instruction count of each loop (SysTick on
the Cortex-M cores, the mcycle CSR on RV32, one per instruction under QEMU's ``-icount shift=0``), a
known 2,000,000-instruction loop that checks the count, the loop and call overhead, the overflow
counters and an FNV-1a hash of every axis' checkpoint image (equal hashes: the same bits on two cores).
:func:`run_core` builds it with the core's compiler and board runtime and runs it:
bench/speed/bench_rv32_icount.py (RV32 beside the M3) and bench/speed/bench_arch.py print the figures,
tests/hil_sim/test_rv32_board.py asserts on them.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from accelnav.codegen.emit_c import emit
from accelnav.hil_sim.targets.qemu import run_to_exit
from accelnav.native.cbuild import BOARD_WARN
from accelnav.resources import firmware_dir

FORMS = (("cov", "covariance"), ("gs", "gain_schedule"))


COMMON = ["-O2", "-std=c99", "-ffreestanding", *BOARD_WARN]


# core -> compiler, flags, runtime folder, linker script, link flags, size tool, qemu machine and binary
CORES = {
    "M3": (
        "arm-none-eabi-gcc",
        ["-mcpu=cortex-m3", "-mthumb", "-masm-syntax-unified"],
        "mps2_an385",
        "mps2_an385.ld",
        ["-nostdlib"],
        "arm-none-eabi-size",
        "mps2-an385",
        "qemu-system-arm",
    ),
    "RV32": (
        "riscv64-unknown-elf-gcc",
        ["-march=rv32imac", "-mabi=ilp32", "--specs=picolibc.specs"],
        "sifive_e",
        "sifive_e.ld",
        ["-nostartfiles"],
        "riscv64-unknown-elf-size",
        "sifive_e",
        "qemu-system-riscv32",
    ),
}


MAIN = r"""
#include "board.h"
#include "accelnav_cov.h"
#include "accelnav_gs.h"

static const int32_t codes[][NAX] = {CODES};
#define N (sizeof codes / sizeof codes[0])

/* the instruction count under -icount shift=0: mcycle on RV32; SysTick ticks x 40 on the M3 */
static uint32_t insns(void)
{
#if defined(__riscv)
    uint32_t v;
    __asm__ volatile(".option push\n.option arch, +zicsr\ncsrr %0, mcycle\n.option pop" : "=r"(v));
    return v;
#else
    return board_ticks() * 40u;
#endif
}

static uint32_t since(uint32_t t0)
{
#if defined(__riscv)
    return insns() - t0;
#else
    return ((board_ticks() - t0 / 40u) & 0x00FFFFFFu) * 40u;
#endif
}

/* exactly 2 instructions per iteration */
__attribute__((noinline)) static void known_loop(uint32_t n)
{
#if defined(__riscv)
    __asm__ volatile("1: addi %0, %0, -1\n bnez %0, 1b\n" : "+r"(n));
#else
    __asm__ volatile("1: subs %0, %0, #1\n bne 1b\n" : "+r"(n)::"cc");
#endif
}

__attribute__((noinline)) static bool empty_step(void *s, int32_t code)
{
    __asm__ volatile("" ::"r"(s), "r"(code) : "memory");
    return code > 0;
}

static void report(const char *name, uint32_t v)
{
    board_puts(name);
    board_puts(" ");
    board_put_u32(v);
    board_puts("\n");
}

static uint32_t fnv(uint32_t h, const uint8_t *b, uint32_t n)
{
    while (n--) {
        h = (h ^ *b++) * 16777619u;
    }
    return h;
}

static uint8_t ck[256]; /* an axis' checkpoint image */

int main(void)
{
    STATES
    uint32_t k, t0;
    board_ticks_start();
    t0 = insns();
    known_loop(1000000u);
    report("calib_2M", since(t0));
    t0 = insns();
    for (k = 0; k < N; ++k) {
        EMPTY
    }
    report("empty", since(t0));
    INITS
    t0 = insns();
    for (k = 0; k < N; ++k) {
        COV
    }
    report("cov", since(t0));
    t0 = insns();
    for (k = 0; k < N; ++k) {
        GS
    }
    report("gs", since(t0));
    report("n", N);
    report("overflow", OVERFLOW);
    report("hash_cov", HASH_COV);
    report("hash_gs", HASH_GS);
    return 0;
}
"""


def driver(model, codes) -> str:
    axes = [a.name for a in model.axes]
    rows = ", ".join("{" + ", ".join(str(int(c)) for c in row) + "}" for row in codes)
    states = " ".join(f"static accelnav_{t}_{a}_t {t}_{a};" for t, _ in FORMS for a in axes)
    inits = " ".join(f"accelnav_{t}_{a}_init(&{t}_{a});" for t, _ in FORMS for a in axes)
    step = {
        t: " ".join(f"accelnav_{t}_{a}_step(&{t}_{a}, codes[k][{j}]);" for j, a in enumerate(axes)) for t, _ in FORMS
    }
    empty = " ".join(f"empty_step(&cov_{a}, codes[k][{j}]);" for j, a in enumerate(axes))
    overflow = " + ".join(f"{t}_{a}.overflow" for t, _ in FORMS for a in axes)
    # the checkpoint image (accelnav_*_save), not the struct: a gain-schedule state points into its table
    hashes = {t: "2166136261u" for t, _ in FORMS}
    for t, _ in FORMS:
        for a in axes:
            size = f"ACCELNAV_{t.upper()}_{a.upper()}_CK_BYTES"
            hashes[t] = f"(accelnav_{t}_{a}_save(&{t}_{a}, ck), fnv({hashes[t]}, ck, {size}))"
    text = MAIN.replace("NAX", str(len(axes))).replace("CODES", rows).replace("STATES", states)
    text = text.replace("INITS", inits).replace("EMPTY", empty).replace("OVERFLOW", overflow)
    text = text.replace("COV\n", step["cov"] + "\n").replace("GS\n", step["gs"] + "\n")
    return text.replace("HASH_COV", hashes["cov"]).replace("HASH_GS", hashes["gs"])


def run_core(core: str, model, main_c: str, tmp: Path, spec: tuple | None = None) -> tuple[dict, dict]:
    """Build both forms and the driver for ``core`` (or ``spec``, a tuple like CORES' values), run it;
    returns (printed counts, flash per form)."""
    cc, flags, board_name, ld, link_flags, size, machine, qemu = spec or CORES[core]
    board = firmware_dir() / "boards" / board_name
    tmp.mkdir(parents=True, exist_ok=True)
    cflags = [*flags, *COMMON]
    flash = {}
    for tag, form in FORMS:
        for name, text in emit(model, form=form, prefix=f"accelnav_{tag}").items():
            (tmp / name).write_text(text)
        obj = tmp / f"accelnav_{tag}.o"
        subprocess.run([cc, *cflags, "-c", str(tmp / f"accelnav_{tag}.c"), "-o", str(obj)], check=True)
        out = subprocess.run([size, str(obj)], check=True, capture_output=True, text=True).stdout
        text, data = (int(x) for x in out.splitlines()[1].split()[:2])
        flash[tag] = text + data
    (tmp / "main.c").write_text(main_c)
    srcs = [tmp / "main.c", board / "startup.c", board.parent / "semihost_rt.c"]
    srcs += [tmp / f"accelnav_{t}.c" for t, _ in FORMS]
    inc = ["-I", str(board), "-I", str(board.parent), "-I", str(tmp)]
    elf = tmp / "bench.elf"
    cmd = [cc, *cflags, *link_flags, *inc, "-T", str(board / ld), *map(str, srcs), "-lgcc", "-o", str(elf)]
    subprocess.run(cmd, check=True)
    # the one way accelnav runs code on the emulator (hil_sim.qemu), with -icount shift=0
    text_out = run_to_exit(elf, icount=True, timeout=300, machine=machine, qemu=qemu)
    vals = {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+) (\d+)$", text_out, re.M)}
    return vals, flash
