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

#define BOARD_CPU_HZ 16000000u
#define BOARD_INSNS_PER_TICK_X2 125u /* 2 x (1 ns per instruction / 62.5 ns per tick) */

void board_puts(const char *s);          /* semihosting SYS_WRITE0 */
void board_put_u32(uint32_t v);          /* decimal, via board_puts */
void board_exit(int status);             /* semihosting SYS_EXIT; never returns */
void board_ticks_start(void);            /* SysTick free-running on the core clock */
uint32_t board_ticks(void);              /* a free-running 24-bit tick count */
uint32_t board_ticks_since(uint32_t t0); /* ticks from t0 to now, modulo 2^24 */

int main(void);

#endif
