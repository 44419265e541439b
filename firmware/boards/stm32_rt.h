/* What the STM32 boards' runtimes share (stm32f103 and its QEMU build stm32vldiscovery, netduino2).
 *
 * The host link on USART1: a receive ring filled by the RXNE interrupt (hardware overruns and a
 * full ring counted as lost bytes) and a transmit ring that the TXE interrupt empties on the part.
 * QEMU's STM32 USART raises no TXE interrupt: the emulated builds (ACN_STM32_QEMU) leave TXEIE off
 * and the main loop calls stm32_link_tx_poll(). The time base: SysTick at 1 kHz on the core clock.
 * This file gives board_uart_write(), board_rx_lost(), board_time_ms(), board_boot_id() and the
 * usart1_handler() and systick_handler() of the vector table; the board sets the USART up. */
#ifndef STM32_RT_H
#define STM32_RT_H

#include <stdbool.h>
#include <stdint.h>

#include "stm32_common.h"

#define STM32_LINK_TX_SIZE 1024u /* powers of two */
#define STM32_LINK_RX_SIZE 128u

void stm32_link_init(usart_t *usart); /* the USART the link runs on, set up by the board */
bool stm32_link_rx(uint8_t *b);       /* the next received byte, if there is one */
bool stm32_link_rx_empty(void);
uint32_t stm32_link_tx_free(void);   /* bytes board_uart_write() can still take */
bool stm32_link_tx_next(uint8_t *b); /* take the next byte to send (a feed that sends it itself) */
bool stm32_link_tx_empty(void);
void stm32_link_tx_poll(void); /* the ring into DR while the USART takes bytes */

void stm32_time_init(uint32_t core_hz); /* SysTick: board_time_ms() counts from here */

#endif
