/* Bare-metal runtime for QEMU's sifive_e (SiFive FE310 as on the HiFive1: RV32IMAC, no FPU): the
 * same services as ../mps2_an385/board.h (console, exit, ticks, reset: ../semihost_rt.c), so that
 * the firmware and the benchmarks run on it with the same calls.
 *
 * Console and exit use RISC-V semihosting (run QEMU with -semihosting). Time base: the CLINT's
 * mtime, which QEMU 7.2 runs at 10 MHz of virtual time (a real FE310 runs it from the 32.768 kHz
 * low-frequency clock, and so do later QEMUs: there board_time_ms() would run slow; only the info
 * frame's uptime reads it). With `-icount shift=0` the mcycle CSR counts instructions exactly. */
#ifndef BOARD_H
#define BOARD_H

#include <stdint.h>

#include "semihost_rt.h" /* the shared runtime: console, exit, ticks, reset */

#define BOARD_CPU_HZ 16000000u  /* the FE310's reset clock (HFROSC); QEMU does not model clocks */
#define BOARD_TICK_HZ 10000000u /* mtime in QEMU 7.2 (emu_txq.c folds board_ticks() with it) */

#endif
