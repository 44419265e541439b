/* The file feed of the emulated boards (mps2_an385, microbit, stm32vldiscovery in QEMU): the
 * stimulus read from a host file and the telemetry written to another, in blocks, through ARM
 * semihosting, instead of one byte per emulator poll through a UART socket.
 *
 * QEMU is started with -semihosting-config enable=on,target=native,arg=accelnav-feed,arg=IN,arg=OUT
 * (file names relative to QEMU's working folder, no spaces). emu_feed_start() finds that command
 * line (SYS_GET_CMDLINE) and opens both files; without it the board runs on its UARTs as before.
 * In feed mode every byte of IN goes to app_rx(APP_CH_HOST): the same channel and the same bytes as
 * the host board's stdin (SIL), commands included. A byte is taken only while the telemetry queue
 * has room for three more frames, as on the UARTs, so nothing is dropped; the queue goes out to OUT
 * when it fills up and at the end. At the end of IN the queue is written out, the files are closed
 * and the emulator exits (SYS_EXIT, status 0; 1 if a file could not be opened or written). */
#ifndef EMU_FEED_H
#define EMU_FEED_H

#include <stdbool.h>
#include <stdint.h>

/* The board's telemetry queue, as the feed sees it (emu_txq.c, or the board's own ring). */
uint32_t emu_txq_free(void);   /* bytes board_uart_write() can still take */
bool emu_txq_next(uint8_t *b); /* the next byte to send, if there is one */

bool emu_feed_start(void); /* true: the host named the files and they are open (feed mode) */
void emu_feed_poll(void);  /* one pass of the loop in feed mode; at the end of IN, exits */

#endif
