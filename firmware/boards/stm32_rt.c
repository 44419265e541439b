/* The STM32 boards' USART1 link: see stm32_rt.h. */
#include "stm32_rt.h"

#include "acn_board.h"

#define TX_SIZE STM32_LINK_TX_SIZE
#define RX_SIZE STM32_LINK_RX_SIZE

static usart_t *link_usart;
static uint8_t tx_ring[TX_SIZE];
static volatile uint32_t tx_head, tx_tail;
static uint8_t rx_ring[RX_SIZE];
static volatile uint32_t rx_head, rx_tail;
static volatile uint32_t rx_lost; /* bytes lost to a full ring or a hardware overrun */
static volatile uint32_t time_ms;

void stm32_time_init(uint32_t core_hz)
{
    SYSTICK->RVR = core_hz / 1000u - 1u;
    SYSTICK->CVR = 0;
    SYSTICK->CSR = 7u; /* core clock, interrupt, enable */
}

void systick_handler(void)
{
    ++time_ms;
}

uint32_t board_time_ms(void)
{
    return time_ms;
}

uint16_t board_boot_id(void)
{
    return 1u; /* no retained counter set up on these boards yet: the value the host board uses too
                */
}

void stm32_link_init(usart_t *usart)
{
    link_usart = usart;
}

bool stm32_link_rx(uint8_t *b)
{
    if (rx_tail == rx_head) {
        return false;
    }
    *b = rx_ring[rx_tail & (RX_SIZE - 1u)];
    ++rx_tail;
    return true;
}

bool stm32_link_rx_empty(void)
{
    return rx_tail == rx_head;
}

uint32_t stm32_link_tx_free(void)
{
    return TX_SIZE - (tx_head - tx_tail);
}

bool stm32_link_tx_next(uint8_t *b)
{
    if (tx_tail == tx_head) {
        return false;
    }
    *b = tx_ring[tx_tail++ & (TX_SIZE - 1u)];
    return true;
}

bool stm32_link_tx_empty(void)
{
    return tx_tail == tx_head;
}

uint32_t board_rx_lost(void)
{
    return rx_lost;
}

bool board_uart_write(const uint8_t *p, size_t n)
{
    size_t i;
    uint32_t head = tx_head;
    if (n > TX_SIZE - (head - tx_tail)) {
        return false;
    }
    for (i = 0; i < n; ++i) {
        tx_ring[head++ & (TX_SIZE - 1u)] = p[i];
    }
    tx_head = head;
#ifndef ACN_STM32_QEMU /* there the main loop empties the ring (stm32_link_tx_poll) */
    irq_disable();
    link_usart->CR1 |= USART_CR1_TXEIE;
    irq_enable();
#endif
    return true;
}

/* The next byte of the ring into DR, or the TXE interrupt off when the ring is empty. */
static void tx_move(void)
{
    if (tx_tail != tx_head) {
        link_usart->DR = tx_ring[tx_tail++ & (TX_SIZE - 1u)];
    } else {
        link_usart->CR1 &= ~USART_CR1_TXEIE;
    }
}

void stm32_link_tx_poll(void)
{
    while (tx_tail != tx_head && (link_usart->SR & USART_SR_TXE)) {
        tx_move();
    }
}

void usart1_handler(void)
{
    uint32_t sr = link_usart->SR;
    if (sr & (USART_SR_RXNE | USART_SR_ORE)) {
        uint8_t b = (uint8_t)link_usart->DR; /* reading DR after SR clears RXNE and ORE */
        if (sr & USART_SR_ORE) {
            ++rx_lost;
        }
        if (rx_head - rx_tail < RX_SIZE) {
            rx_ring[rx_head++ & (RX_SIZE - 1u)] = b;
        } else {
            ++rx_lost;
        }
    }
    if ((sr & USART_SR_TXE) && (link_usart->CR1 & USART_CR1_TXEIE)) {
        tx_move();
    }
}
