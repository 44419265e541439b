/* accelnav board layer for QEMU's microbit (nRF51822, Cortex-M0, 16 MHz), beside the bare-metal
 * runtime of this folder (startup.c, board.h, nrf51822.ld).
 *
 * The nRF51 has one UART (0x40002000, QEMU's only -serial): telemetry out, and in, on the same
 * line, command frames and the stimulus feed standing in for the ADC or the timer capture (one
 * stimulus frame is one sample; the frame type tells them apart, as on the host board). The run is
 * paced by the feed and reproducible. A received byte is taken only while the telemetry queue has
 * room for three more frames: the board never drops telemetry, it slows the feed down (QEMU's UART
 * holds at most 6 bytes and stops reading its socket when they are not taken). When QEMU's command
 * line names a file feed (emu_feed.h: how PIL runs), input and telemetry go through files over
 * semihosting instead, and the UART is left alone.
 *
 * Time base: SysTick free-running on the core clock (board_ticks of the runtime), folded into
 * milliseconds on every pass of the loop. */
#include "acn_board.h"
#include "board.h"
#include "emu_feed.h"
#include "emu_txq.h"

/* nRF51 UART registers (nRF51 Series Reference Manual v3.0, chapter 29), offsets in words */
#define UART0_BASE 0x40002000u
#define UART_REG(off) (*(volatile uint32_t *)(UART0_BASE + (off)))
#define UART_STARTRX UART_REG(0x000u)
#define UART_STARTTX UART_REG(0x008u)
#define UART_RXDRDY UART_REG(0x108u) /* event: a byte is in RXD */
#define UART_TXDRDY UART_REG(0x11cu) /* event: the byte in TXD went out */
#define UART_ERRORSRC UART_REG(0x480u)
#define UART_ENABLE UART_REG(0x500u)
#define UART_PSELTXD UART_REG(0x50cu)
#define UART_PSELRXD UART_REG(0x514u)
#define UART_RXD UART_REG(0x518u)
#define UART_TXD UART_REG(0x51cu)
#define UART_BAUDRATE UART_REG(0x524u)
#define UART_ENABLE_ON 4u
#define UART_BAUD_115200 0x01d7e000u
#define UART_ERRORSRC_OVERRUN 1u
#define PIN_TX 24u /* micro:bit edge connector USB bridge: P0.24 TX, P0.25 RX */
#define PIN_RX 25u

static bool tx_busy;     /* a byte is in TXD and TXDRDY has not come yet */
static uint32_t rx_lost; /* bytes the UART dropped (overrun) */
static bool feed;        /* the file feed instead of the UART (emu_feed.h) */

void board_init(void)
{
    UART_ENABLE = 0;
    UART_PSELTXD = PIN_TX;
    UART_PSELRXD = PIN_RX;
    UART_BAUDRATE = UART_BAUD_115200; /* the emulator does not pace the bytes, a real nRF51 would */
    UART_ENABLE = UART_ENABLE_ON;
    UART_RXDRDY = 0;
    UART_TXDRDY = 0;
    UART_STARTTX = 1u;
    UART_STARTRX = 1u;
    tx_busy = false;
    rx_lost = 0;
    board_ticks_start();
    emu_txq_init();
    feed = emu_feed_start();
}

uint8_t board_id(void)
{
    return ACNF_BOARD_MICROBIT;
}

uint16_t board_boot_id(void)
{
    return 1u; /* no retained counter set up on this board yet: the value the host board uses too */
}

uint32_t board_rx_lost(void)
{
    return rx_lost;
}

bool board_poll(void)
{
    uint8_t b;
    emu_clock_update();
    if (feed) {
        emu_feed_poll();
        return true;
    }
    if (tx_busy && UART_TXDRDY) {
        tx_busy = false;
    }
    if (!tx_busy && emu_txq_next(&b)) {
        UART_TXDRDY = 0;
        UART_TXD = b;
        tx_busy = true;
    }
    if (UART_ERRORSRC & UART_ERRORSRC_OVERRUN) {
        UART_ERRORSRC = UART_ERRORSRC_OVERRUN; /* write 1 to clear */
        ++rx_lost;
    }
    if (emu_txq_free() < 3u * ACNF_MAX_UP_WIRE) {
        return true; /* let the queue drain before taking input that makes more */
    }
    if (UART_RXDRDY) {
        UART_RXDRDY = 0; /* clear the event first: a byte left in the FIFO raises it again */
        b = (uint8_t)UART_RXD;
        app_rx(APP_CH_HOST, &b, 1);
    }
    return true;
}
