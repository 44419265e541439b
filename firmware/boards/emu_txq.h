/* The telemetry queue and millisecond clock the emulated boards share (mps2_an385, microbit).
 * board_uart_write() and board_time_ms() of acn_board.h are implemented here; each board's
 * board_poll() feeds its own UART (or the file feed, emu_feed.h) from emu_txq_next() and calls
 * emu_clock_update(). */
#ifndef EMU_TXQ_H
#define EMU_TXQ_H

#include <stdbool.h>
#include <stdint.h>

void emu_txq_init(void);       /* an empty queue, the clock from now (after board_ticks_start) */
uint32_t emu_txq_free(void);   /* bytes board_uart_write() can still take */
bool emu_txq_next(uint8_t *b); /* the next byte to send, if there is one */
void emu_clock_update(void);   /* fold the SysTick ticks since the last call into board_time_ms() */

#endif
