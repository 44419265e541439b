/* accelnav board layer for QEMU's mps2-an385 (Cortex-M3, 25 MHz), beside the
 * bare-metal runtime of this folder (startup.c, board.h, mps2_an385.ld).
 *
 * UART0 (CMSDK APB UART at 0x40004000, QEMU's first -serial): telemetry out,
 * commands in. UART1 (0x40005000, the second -serial): the stimulus feed
 * standing in for the ADC or the timer capture, which the emulator lacks: one
 * stimulus frame (the same framing as everything else) is one sample, so the
 * run is paced by the feed and reproducible. A stimulus byte is read only
 * while the telemetry queue has room for three more frames: the emulated board
 * never drops telemetry, it slows the feed down instead (commands likewise). When QEMU's command
 * line names a file feed (emu_feed.h: how PIL runs), input and telemetry go through files over
 * semihosting instead, and the UARTs are left alone.
 *
 * Time base: SysTick free-running on the core clock (board_ticks of the
 * runtime), folded into milliseconds on every pass of the loop. */
#include "acn_board.h"
#include "board.h"
#include "emu_feed.h"
#include "emu_txq.h"

/* CMSDK APB UART registers (ARM DDI 0479, "APB UART") */
typedef struct {
    volatile uint32_t DATA; /* 0x00: rx/tx byte */
    volatile uint32_t
        STATE;              /* 0x04: bit0 TX full, bit1 RX full, bit2 TX overrun, bit3 RX overrun */
    volatile uint32_t CTRL; /* 0x08: bit0 TX enable, bit1 RX enable, bits 2..5 interrupt enables */
    volatile uint32_t INTSTAT; /* 0x0c: read status / write 1 to clear */
    volatile uint32_t BAUDDIV; /* 0x10: >= 16 */
} cmsdk_uart_t;

#define UART0 ((cmsdk_uart_t *)0x40004000u)
#define UART1 ((cmsdk_uart_t *)0x40005000u)
#define UART_STATE_TXFULL 1u
#define UART_STATE_RXFULL 2u
#define UART_STATE_RXOVERRUN 8u /* write 1 to clear */
#define UART_CTRL_TXEN 1u
#define UART_CTRL_RXEN 2u
/* 115200 baud; the emulator does not pace the bytes, a real MPS2 would */
#define UART_BAUDDIV (BOARD_CPU_HZ / 115200u)

static uint32_t rx_lost; /* bytes the UARTs dropped (RX overrun) */
static bool feed;        /* the file feed instead of the UARTs (emu_feed.h) */

static void uart_init(cmsdk_uart_t *u)
{
    u->CTRL = 0;
    u->BAUDDIV = UART_BAUDDIV;
    u->INTSTAT = 0xfu;
    u->CTRL = UART_CTRL_TXEN | UART_CTRL_RXEN;
}

void board_init(void)
{
    uart_init(UART0);
    uart_init(UART1);
    rx_lost = 0;
    board_ticks_start();
    emu_txq_init();
    feed = emu_feed_start();
}

uint8_t board_id(void)
{
    return ACNF_BOARD_MPS2_AN385;
}

uint16_t board_boot_id(void)
{
    return 1u; /* no retained counter set up on this board yet: the value the host board uses too */
}

uint32_t board_rx_lost(void)
{
    return rx_lost;
}

static void rx_overrun_check(cmsdk_uart_t *u)
{
    if (u->STATE & UART_STATE_RXOVERRUN) {
        u->STATE = UART_STATE_RXOVERRUN;
        ++rx_lost;
    }
}

bool board_poll(void)
{
    uint8_t b;
    emu_clock_update();
    if (feed) {
        emu_feed_poll();
        return true;
    }
    while (!(UART0->STATE & UART_STATE_TXFULL) && emu_txq_next(&b)) {
        UART0->DATA = b;
    }
    rx_overrun_check(UART0);
    rx_overrun_check(UART1);
    if (emu_txq_free() < 3u * ACNF_MAX_UP_WIRE) {
        return true; /* let the queue drain before taking input that makes more */
    }
    if (UART0->STATE & UART_STATE_RXFULL) {
        b = (uint8_t)UART0->DATA;
        app_rx(APP_CH_HOST, &b, 1);
    }
    if (UART1->STATE & UART_STATE_RXFULL) {
        b = (uint8_t)UART1->DATA;
        app_rx(APP_CH_STIM, &b, 1);
    }
    return true;
}
