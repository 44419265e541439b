/* The host link of the STM32 boards on their USART1: a receive ring filled by the RXNE interrupt
 * (hardware overruns and a full ring counted as lost bytes) and a transmit ring that the TXE
 * interrupt empties on the part. QEMU's STM32 USART raises no TXE interrupt: the emulated builds
 * (ACN_STM32_QEMU) leave TXEIE off and the main loop calls stm32_link_tx_poll(). This file gives
 * board_uart_write(), board_rx_lost() and usart1_handler(); the board sets the USART up. */
#ifndef STM32_LINK_H
#define STM32_LINK_H

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

#endif
