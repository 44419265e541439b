/* The bare-metal runtime both emulated boards share (QEMU mps2-an385, Cortex-M3, and microbit,
 * Cortex-M0): semihosting console and exit, a SysTick tick counter, the fault handler and the reset
 * handler (.data copied, .bss cleared, main()). Each board's startup.c keeps only its vector table
 * and what is its own; its board.h gives the clock constants. Run QEMU with -semihosting. */
#ifndef SEMIHOST_RT_H
#define SEMIHOST_RT_H

#include <stdint.h>

void board_puts(const char *s);          /* semihosting SYS_WRITE0 */
void board_put_u32(uint32_t v);          /* decimal, via board_puts */
void board_exit(int status);             /* semihosting SYS_EXIT; never returns */
void board_ticks_start(void);            /* SysTick free-running on the core clock */
uint32_t board_ticks(void);              /* a free-running 24-bit tick count */
uint32_t board_ticks_since(uint32_t t0); /* ticks from t0 to now, modulo 2^24 */
void board_reset(void);                  /* the reset handler */
void board_fault(void);                  /* NMI and fault handler: says "fault", exits 1 */

int main(void);

#endif
