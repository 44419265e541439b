/* The few STM32F205 registers the netduino2 board uses (RM0033), written for accelnav: RCC, FLASH,
 * GPIO, TIM3, ADC1, USART1 (the USART and SysTick blocks: stm32_common.h). Register blocks are
 * structs laid out at their reference-manual offsets. The F2 moved its peripherals from the F1's
 * addresses and changed RCC, GPIO and the ADC (F1 code does not carry over); its timers and USARTs
 * kept the F1's layout. */
#ifndef STM32F2_REGS_H
#define STM32F2_REGS_H

#include "stm32_common.h" /* REG, USART, SysTick, NVIC */

typedef struct {
    REG CR, PLLCFGR, CFGR, CIR, AHB1RSTR, AHB2RSTR, AHB3RSTR, RESERVED0, APB1RSTR, APB2RSTR,
        RESERVED1[2], AHB1ENR, AHB2ENR, AHB3ENR, RESERVED2, APB1ENR, APB2ENR;
} rcc_t;
typedef struct {
    REG ACR;
} flash_t;
typedef struct {
    REG MODER, OTYPER, OSPEEDR, PUPDR, IDR, ODR, BSRR, LCKR, AFR[2];
} gpio_t;
typedef struct {
    REG CR1, CR2, SMCR, DIER, SR, EGR, CCMR1, CCMR2, CCER, CNT, PSC, ARR;
} tim_t;
typedef struct {
    REG SR, CR1, CR2, SMPR1, SMPR2, JOFR[4], HTR, LTR, SQR1, SQR2, SQR3, JSQR, JDR[4], DR;
} adc_t;

#define RCC ((rcc_t *)0x40023800u)
#define FLASH ((flash_t *)0x40023c00u)
#define GPIOA ((gpio_t *)0x40020000u)
#define TIM3 ((tim_t *)0x40000400u)
#define ADC1 ((adc_t *)0x40012000u)
#define ADC_CCR ((REG *)0x40012304u) /* common to the three ADCs: the prescaler */
#define USART1 ((usart_t *)0x40011000u)

/* RCC */
#define RCC_CR_HSION (1u << 0)
#define RCC_CR_HSIRDY (1u << 1)
#define RCC_CR_PLLON (1u << 24)
#define RCC_CR_PLLRDY (1u << 25)
#define RCC_PLLCFGR(m, n, p, q) ((m) | ((n) << 6) | ((((p) / 2u) - 1u) << 16) | ((q) << 24))
#define RCC_CFGR_SW_PLL (2u << 0)
#define RCC_CFGR_SWS_MASK (3u << 2)
#define RCC_CFGR_SWS_PLL (2u << 2)
#define RCC_CFGR_PPRE1_DIV4 (5u << 10)
#define RCC_CFGR_PPRE2_DIV2 (4u << 13)
#define RCC_AHB1ENR_GPIOAEN (1u << 0)
#define RCC_APB1ENR_TIM3EN (1u << 1)
#define RCC_APB2ENR_USART1EN (1u << 4)
#define RCC_APB2ENR_ADC1EN (1u << 8)
#define FLASH_ACR_LATENCY3 (3u << 0)
#define FLASH_ACR_PRFTEN (1u << 8)
#define FLASH_ACR_ICEN (1u << 9)
#define FLASH_ACR_DCEN (1u << 10)

/* GPIO: MODER 2 bits a pin, AFR 4 bits a pin */
#define GPIO_MODE_AF 2u
#define GPIO_MODE_ANALOG 3u
#define GPIO_AF_USART1 7u

/* TIM */
#define TIM_CR1_CEN (1u << 0)
#define TIM_DIER_UIE (1u << 0)
#define TIM_SR_UIF (1u << 0)
#define TIM_EGR_UG (1u << 0)

/* ADC */
#define ADC_SR_EOC (1u << 1)
#define ADC_CR1_RES_SHIFT 24
#define ADC_CR2_ADON (1u << 0)
#define ADC_CR2_SWSTART (1u << 30)
#define ADC_CCR_ADCPRE_DIV4 (1u << 16)

/* IRQ numbers (STM32F2xx): the F1's for TIM3 and USART1, so the stm32f103 vector table serves */
#define IRQ_TIM3 29
#define IRQ_USART1 37

#endif
