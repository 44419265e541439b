/* accelnav board layer for QEMU's sifive_e (SiFive FE310, RV32IMAC, no FPU), beside the bare-metal
 * runtime of this folder (startup.c, board.h, sifive_e.ld).
 *
 * QEMU models one of the FE310's two UARTs (UART0 at 0x10013000, its only -serial): telemetry out,
 * and in, on the same line, command frames and the stimulus feed standing in for the ADC or the
 * timer capture (one stimulus frame is one sample; the frame type tells them apart, as on the host
 * board and the microbit). A received byte is taken only while the telemetry queue has room for
 * three more frames: the board never drops telemetry, it slows the feed down (QEMU's UART holds 8
 * bytes and stops reading its socket when they are not taken). When QEMU's command line names a
 * file feed (emu_feed.h: how PIL runs), input and telemetry go through files over semihosting
 * instead, and the UART is left alone.
 *
 * The SiFive UART has no overrun flag: a real FE310 loses bytes its 8-byte receive FIFO cannot
 * hold without saying so, so board_rx_lost() stays 0 here (QEMU loses none).
 *
 * Time base: the CLINT's mtime (board_ticks of the runtime), folded into milliseconds on every pass
 * of the loop. */
#include "acn_board.h"
#include "board.h"
#include "emu_feed.h"
#include "emu_txq.h"

/* SiFive UART registers (FE310-G002 manual, chapter 18), offsets in bytes */
#define UART0_BASE 0x10013000u
#define UART_REG(off) (*(volatile uint32_t *)(UART0_BASE + (off)))
#define UART_TXDATA UART_REG(0x00u) /* write: a byte; read: bit 31 = transmit FIFO full */
#define UART_RXDATA UART_REG(0x04u) /* read: bit 31 = empty, else the byte in bits 0..7 */
#define UART_TXCTRL UART_REG(0x08u) /* bit 0: transmit enable */
#define UART_RXCTRL UART_REG(0x0cu) /* bit 0: receive enable */
#define UART_DIV UART_REG(0x18u)    /* baud = core clock / (div + 1) */
#define UART_FIFO_FLAG 0x80000000u
#define UART_EN 1u

static bool feed; /* the file feed instead of the UART (emu_feed.h) */

void board_init(void)
{
    UART_DIV =
        BOARD_CPU_HZ / 115200u - 1u; /* the emulator does not pace the bytes, an FE310 would */
    UART_TXCTRL = UART_EN;
    UART_RXCTRL = UART_EN;
    board_ticks_start();
    emu_txq_init();
    feed = emu_feed_start();
}

uint8_t board_id(void)
{
    return ACNF_BOARD_SIFIVE_E;
}

uint16_t board_boot_id(void)
{
    return 1u; /* no retained counter set up on this board yet: the value the host board uses too */
}

uint32_t board_rx_lost(void)
{
    return 0u; /* see above: the SiFive UART cannot tell */
}

bool board_poll(void)
{
    uint8_t b;
    uint32_t rx;
    emu_clock_update();
    if (feed) {
        emu_feed_poll();
        return true;
    }
    while (!(UART_TXDATA & UART_FIFO_FLAG) && emu_txq_next(&b)) {
        UART_TXDATA = b;
    }
    if (emu_txq_free() < 3u * ACNF_MAX_UP_WIRE) {
        return true; /* let the queue drain before taking input that makes more */
    }
    rx = UART_RXDATA; /* reading takes the byte out of the FIFO */
    if (!(rx & UART_FIFO_FLAG)) {
        b = (uint8_t)rx;
        app_rx(APP_CH_HOST, &b, 1);
    }
    return true;
}
