/* accelnav board layer for the ATmega328P (Arduino Uno: 8-bit AVR at 16 MHz, 32 KiB flash, 2 KiB
 * RAM, a 16-bit int), run in simavr for PIL.
 *
 * USART0 (the Uno's USB-serial line, D0/D1) at 250000 baud 8N1 (UBRR0 7 with U2X0: exact at 16 MHz)
 * carries everything, as on the one-UART microbit: telemetry out, and commands and stimulus frames
 * in (the frame type tells them apart; one channel, APP_CH_HOST, the host board's). The ADC is not
 * read: a stimulus frame stands in for it, one per sample, so a run is paced by its feed and
 * reproducible. The receiver is polled; a byte is taken only while the telemetry ring has room for
 * the most one received byte can make the application send (below), so nothing is ever dropped and
 * the sender is slowed down instead (simavr holds the bytes in its UART FIFO and says XOFF).
 *
 * PB5 (D13, the Uno's LED) is high while the board is idle: nothing queued to send and nothing
 * taken in its last pass. simavr's harness (simavr_feed.c) ends a run when it has fed its last byte
 * and then sees PB5 rise; on a real Uno the LED lights when the link is quiet.
 *
 * Time base: Timer1 free-running at clk/64 (4 us), folded into milliseconds on every pass of the
 * loop (it wraps in 262 ms; one pass takes far less). */
#include <avr/io.h>

#include "acn_board.h"

#define BOARD_CPU_HZ 16000000UL
#define UART_UBRR 7u      /* U2X0: 16 MHz / (8 * (7 + 1)) = 250000 baud */
#define TICKS_PER_MS 250u /* Timer1 at 16 MHz / 64 */
#define IDLE_PIN (1u << PB5)

#define TX_NEED ACN_TX_NEED /* acn_board.h */
/* The ring: what one received byte can make the application send (a byte is taken only while the
 * ring has that much room, so no frame is ever refused), plus 64 B of slack, so that the board goes
 * on reading while the last telemetry drains. Sized by the model, not rounded up to a power of two:
 * that took 1 KiB for three axes, more than the part's RAM leaves them (with 64 B, a 3-axis image
 * takes 1 206 B static beside the 768 B stack reserve). The power-of-two rings left two axes 78 B;
 * with 14 B, simavr's feed lost the last input bytes of some runs (test_hil's atmega328p runs: too
 * few sample frames; the cause in simavr's UART not found); 64 B and 128 B pass them. */
#define TX_SIZE (TX_NEED + 64u)

static uint8_t tx_ring[TX_SIZE]; /* indices wrap at TX_SIZE by a compare: any size */
static uint16_t tx_head;         /* next write */
static uint16_t tx_tail;         /* next send */
static uint16_t tx_used;         /* bytes queued */
static uint32_t rx_lost;         /* bytes the receiver lost (data overrun) */
static uint32_t time_ms;
static uint16_t tick_last;
static uint16_t tick_rem;

static uint16_t tx_free(void)
{
    return (uint16_t)(TX_SIZE - tx_used);
}

void board_init(void)
{
    UBRR0H = 0;
    UBRR0L = UART_UBRR;
    UCSR0A = (uint8_t)(1u << U2X0);
    UCSR0C = (uint8_t)((1u << UCSZ01) | (1u << UCSZ00)); /* 8N1 */
    UCSR0B = (uint8_t)((1u << RXEN0) | (1u << TXEN0));
    TCCR1A = 0;
    TCCR1B = (uint8_t)((1u << CS11) | (1u << CS10)); /* normal mode, clk/64 */
    DDRB |= (uint8_t)IDLE_PIN;
    tx_head = tx_tail = tx_used = 0;
    rx_lost = 0;
    time_ms = 0;
    tick_rem = 0;
    tick_last = TCNT1;
}

bool board_uart_write(const uint8_t *p, size_t n)
{
    size_t i;
    if (n > tx_free()) {
        return false;
    }
    for (i = 0; i < n; ++i) {
        tx_ring[tx_head] = p[i];
        if (++tx_head == TX_SIZE) {
            tx_head = 0;
        }
    }
    tx_used = (uint16_t)(tx_used + n);
    return true;
}

uint32_t board_time_ms(void)
{
    return time_ms;
}

uint8_t board_id(void)
{
    return ACNF_BOARD_ATMEGA328P;
}

uint16_t board_boot_id(void)
{
    return 1u; /* no counter kept in EEPROM yet: the value the host board uses too */
}

uint32_t board_rx_lost(void)
{
    return rx_lost;
}

static void clock_update(void)
{
    uint16_t now = TCNT1;
    tick_rem += (uint16_t)(now - tick_last);
    tick_last = now;
    time_ms += tick_rem / TICKS_PER_MS;
    tick_rem %= TICKS_PER_MS;
}

bool board_poll(void)
{
    bool busy;
    clock_update();
    if ((UCSR0A & (1u << UDRE0)) && tx_used != 0u) {
        UDR0 = tx_ring[tx_tail];
        if (++tx_tail == TX_SIZE) {
            tx_tail = 0;
        }
        --tx_used;
    }
    busy = tx_used != 0u;
    if (tx_free() >= TX_NEED && (UCSR0A & (1u << RXC0))) {
        uint8_t b;
        if (UCSR0A & (1u << DOR0)) { /* a byte was lost before this one (cleared by reading UDR0) */
            ++rx_lost;
        }
        b = UDR0;
        app_rx(APP_CH_HOST, &b, 1);
        busy = true;
    }
    if (busy) {
        PORTB &= (uint8_t)~IDLE_PIN;
    } else {
        PORTB |= (uint8_t)IDLE_PIN;
    }
    return true;
}
