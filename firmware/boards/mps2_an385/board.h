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

#define BOARD_CPU_HZ 25000000u
#define BOARD_INSNS_PER_TICK 40u /* 1 ns per instruction (icount shift 0) / 40 ns per tick */

void board_puts(const char *s);          /* semihosting SYS_WRITE0 */
void board_uart_puts(const char *s);     /* CMSDK UART0 at 0x40004000 */
void board_put_u32(uint32_t v);          /* decimal, via board_puts */
void board_exit(int status);             /* semihosting SYS_EXIT; never returns */
void board_ticks_start(void);            /* SysTick free-running on the core clock */
uint32_t board_ticks(void);              /* a free-running 24-bit tick count */
uint32_t board_ticks_since(uint32_t t0); /* ticks from t0 to now, modulo 2^24 */

int main(void);

#endif
