/* Bare-metal runtime for QEMU's microbit (nRF51822, Cortex-M0, 16 MHz): startup, console, exit,
 * an instruction counter. The same services as ../mps2_an385/board.h, so that the codegen
 * benchmark and the firmware run on either core with the same calls.
 *
 * Console and exit use ARM semihosting (run QEMU with -semihosting). With `-icount shift=0` every
 * instruction advances the virtual clock by 1 ns; SysTick runs on the 16 MHz core clock, so one
 * tick is 62.5 instructions: BOARD_INSNS_PER_TICK_X2 (125) is twice that, kept an integer. */
#ifndef BOARD_H
#define BOARD_H

#include <stdint.h>

#include "semihost_rt.h" /* the shared runtime: console, exit, ticks, reset */

#define BOARD_CPU_HZ 16000000u
#define BOARD_INSNS_PER_TICK_X2 125u /* 2 x (1 ns per instruction / 62.5 ns per tick) */

#endif
