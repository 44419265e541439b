/* The few STM32F103 registers this firmware uses (RM0008 rev 21), written for
 * accelnav: RCC, FLASH, GPIO, TIM2..4, ADC1, DMA1, USART1 (and USART2, the
 * emulator's stimulus feed), SysTick, NVIC.
 * Register blocks are structs laid out at their reference-manual offsets. */
#ifndef STM32F103_REGS_H
#define STM32F103_REGS_H

#include "stm32_common.h" /* REG, USART, SysTick, NVIC */

typedef struct {
    REG CR, CFGR, CIR, APB2RSTR, APB1RSTR, AHBENR, APB2ENR, APB1ENR, BDCR, CSR;
} rcc_t;
typedef struct {
    REG ACR, KEYR, OPTKEYR, SR, CR, AR, RESERVED, OBR, WRPR;
} flash_t;
typedef struct {
    REG CRL, CRH, IDR, ODR, BSRR, BRR, LCKR;
} gpio_t;
typedef struct {
    REG CR1, CR2, SMCR, DIER, SR, EGR, CCMR1, CCMR2, CCER, CNT, PSC, ARR, RCR, CCR1, CCR2, CCR3,
        CCR4, BDTR, DCR, DMAR;
} tim_t;
typedef struct {
    REG SR, CR1, CR2, SMPR1, SMPR2, JOFR1, JOFR2, JOFR3, JOFR4, HTR, LTR, SQR1, SQR2, SQR3, JSQR,
        JDR1, JDR2, JDR3, JDR4, DR;
} adc_t;
typedef struct {
    REG CCR, CNDTR, CPAR, CMAR, RESERVED;
} dma_channel_t;
typedef struct {
    REG ISR, IFCR;
    dma_channel_t CH[7]; /* CH[0] is channel 1 */
} dma_t;

#define RCC ((rcc_t *)0x40021000u)
#define FLASH ((flash_t *)0x40022000u)
#define GPIOA ((gpio_t *)0x40010800u)
#define GPIOB ((gpio_t *)0x40010c00u)
#define TIM2 ((tim_t *)0x40000000u)
#define TIM3 ((tim_t *)0x40000400u)
#define TIM4 ((tim_t *)0x40000800u)
#define ADC1 ((adc_t *)0x40012400u)
#define DMA1 ((dma_t *)0x40020000u)
#define USART1 ((usart_t *)0x40013800u)
#define USART2 ((usart_t *)0x40004400u)

/* RCC */
#define RCC_CR_HSEON (1u << 16)
#define RCC_CR_HSERDY (1u << 17)
#define RCC_CR_PLLON (1u << 24)
#define RCC_CR_PLLRDY (1u << 25)
#define RCC_CFGR_SW_PLL (2u << 0)
#define RCC_CFGR_SWS_MASK (3u << 2)
#define RCC_CFGR_SWS_PLL (2u << 2)
#define RCC_CFGR_PPRE1_DIV2 (4u << 8)
#define RCC_CFGR_ADCPRE_DIV6 (2u << 14)
#define RCC_CFGR_PLLSRC_HSE (1u << 16)
#define RCC_CFGR_PLLMUL9 (7u << 18)
#define RCC_AHBENR_DMA1EN (1u << 0)
#define RCC_APB2ENR_AFIOEN (1u << 0)
#define RCC_APB2ENR_IOPAEN (1u << 2)
#define RCC_APB2ENR_IOPBEN (1u << 3)
#define RCC_APB2ENR_ADC1EN (1u << 9)
#define RCC_APB2ENR_USART1EN (1u << 14)
#define RCC_APB1ENR_TIM2EN (1u << 0)
#define RCC_APB1ENR_TIM3EN (1u << 1)
#define RCC_APB1ENR_TIM4EN (1u << 2)
#define RCC_APB1ENR_USART2EN (1u << 17)
#define FLASH_ACR_LATENCY2 (2u << 0)
#define FLASH_ACR_PRFTBE (1u << 4)

/* GPIO: a 4-bit field per pin in CRL (0..7) / CRH (8..15) */
#define GPIO_ANALOG 0x0u
#define GPIO_INPUT_FLOATING 0x4u
#define GPIO_AF_PUSHPULL_50MHZ 0xbu

/* TIM */
#define TIM_CR1_CEN (1u << 0)
#define TIM_CR2_MMS_UPDATE (2u << 4)
#define TIM_SMCR_SMS_RESET (4u << 0)
#define TIM_SMCR_TS_TI1FP1 (5u << 4)
#define TIM_DIER_UIE (1u << 0)
#define TIM_DIER_CC1IE (1u << 1)
#define TIM_SR_UIF (1u << 0)
#define TIM_SR_CC1IF (1u << 1)
#define TIM_SR_CC1OF (1u << 9)
#define TIM_CCMR1_CC1S_TI1 (1u << 0)
#define TIM_CCMR1_CC2S_TI1 (2u << 8)
#define TIM_CCER_CC1E (1u << 0)
#define TIM_CCER_CC2E (1u << 4)
#define TIM_CCER_CC2P (1u << 5)
#define TIM_EGR_UG (1u << 0)

/* ADC */
#define ADC_CR1_SCAN (1u << 8)
#define ADC_CR2_ADON (1u << 0)
#define ADC_CR2_CAL (1u << 2)
#define ADC_CR2_RSTCAL (1u << 3)
#define ADC_CR2_DMA (1u << 8)
#define ADC_CR2_EXTSEL_TIM3_TRGO (4u << 17)
#define ADC_CR2_EXTTRIG (1u << 20)

/* DMA channel */
#define DMA_CCR_EN (1u << 0)
#define DMA_CCR_TCIE (1u << 1)
#define DMA_CCR_CIRC (1u << 5)
#define DMA_CCR_MINC (1u << 7)
#define DMA_CCR_PSIZE16 (1u << 8)
#define DMA_CCR_MSIZE16 (1u << 10)
#define DMA_IFCR_CGIF1 (1u << 0)

/* IRQ numbers (STM32F103 medium density) */
#define IRQ_DMA1_CH1 11
#define IRQ_TIM2 28
#define IRQ_TIM3 29
#define IRQ_TIM4 30
#define IRQ_USART1 37

#endif
