/* The telemetry queue and millisecond clock of the emulated boards: see emu_txq.h. */
#include "emu_txq.h"

#include "acn_board.h"
#include "board.h"

/* the rate of board_ticks(): the core clock on the Cortex-M boards (SysTick), another on RV32 */
#ifndef BOARD_TICK_HZ
#define BOARD_TICK_HZ BOARD_CPU_HZ
#endif

#define TX_SIZE 2048u /* power of two */
static uint8_t tx_ring[TX_SIZE];
static uint32_t tx_head; /* next write */
static uint32_t tx_tail; /* next send */

static uint32_t time_ms;
static uint32_t tick_last;
static uint32_t tick_rem; /* ticks not yet folded into time_ms */

void emu_txq_init(void)
{
    tx_head = tx_tail = 0;
    tick_last = board_ticks();
    time_ms = tick_rem = 0;
}

uint32_t emu_txq_free(void)
{
    return TX_SIZE - (tx_head - tx_tail);
}

bool board_uart_write(const uint8_t *p, size_t n)
{
    size_t i;
    if (n > emu_txq_free()) {
        return false;
    }
    for (i = 0; i < n; ++i) {
        tx_ring[tx_head++ & (TX_SIZE - 1u)] = p[i];
    }
    return true;
}

bool emu_txq_next(uint8_t *b)
{
    if (tx_tail == tx_head) {
        return false;
    }
    *b = tx_ring[tx_tail++ & (TX_SIZE - 1u)];
    return true;
}

uint32_t board_time_ms(void)
{
    return time_ms;
}

void emu_clock_update(void)
{
    uint32_t now = board_ticks();
    tick_rem += (now - tick_last) & 0x00ffffffu; /* 24-bit counter */
    tick_last = now;
    time_ms += tick_rem / (BOARD_TICK_HZ / 1000u);
    tick_rem %= BOARD_TICK_HZ / 1000u;
}
