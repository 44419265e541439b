/* Bare-metal runtime for QEMU's mps2-an385 (Cortex-M3): startup, console, exit, a cycle-free
 * instruction counter. Everything that runs code on the emulator goes through this file and
 * startup.c; nothing here is specific to accelnav.
 *
 * Console and exit use ARM semihosting (run QEMU with -semihosting); UART0 output is there
 * too for a run without semihosting. With `-icount shift=0` every instruction advances the
 * virtual clock by 1 ns, so SysTick on the 25 MHz core clock ticks once per 40 instructions:
 * board_ticks() differences times BOARD_INSNS_PER_TICK count instructions deterministically. */
#ifndef BOARD_H
#define BOARD_H

#include <stdint.h>

#include "semihost_rt.h" /* the shared runtime: console, exit, ticks, reset */

#define BOARD_CPU_HZ 25000000u
#define BOARD_INSNS_PER_TICK 40u /* 1 ns per instruction (icount shift 0) / 40 ns per tick */

void board_uart_puts(const char *s); /* CMSDK UART0 at 0x40004000 */

#endif
