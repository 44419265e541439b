/* What the STM32 boards share (stm32f103 and its QEMU build stm32vldiscovery, netduino2): the USART
 * and SysTick register blocks, which the F1, F2 and F4 lay out alike, the NVIC enable and the
 * interrupt mask. Each part's register header includes this one and adds its own peripherals. */
#ifndef STM32_COMMON_H
#define STM32_COMMON_H

#include <stdint.h>

#define REG volatile uint32_t

typedef struct {
    REG SR, DR, BRR, CR1, CR2, CR3, GTPR;
} usart_t;
typedef struct {
    REG CSR, RVR, CVR, CALIB;
} systick_t;

#define SYSTICK ((systick_t *)0xe000e010u)
#define NVIC_ISER ((REG *)0xe000e100u) /* ISER[n]: bit k enables IRQ 32 n + k */

/* USART */
#define USART_SR_ORE (1u << 3)
#define USART_SR_RXNE (1u << 5)
#define USART_SR_TXE (1u << 7)
#define USART_CR1_RE (1u << 2)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RXNEIE (1u << 5)
#define USART_CR1_TXEIE (1u << 7)
#define USART_CR1_UE (1u << 13)

static inline void nvic_enable(int irq)
{
    NVIC_ISER[irq >> 5] = 1u << (irq & 31);
}

static inline void irq_disable(void)
{
    __asm__ volatile("cpsid i" ::: "memory");
}

static inline void irq_enable(void)
{
    __asm__ volatile("cpsie i" ::: "memory");
}

#endif
