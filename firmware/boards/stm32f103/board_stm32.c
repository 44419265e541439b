/* accelnav board layer for an STM32F103C8 ("blue pill") with an 8 MHz crystal.
 *
 * Clocks: HSE 8 MHz -> PLL x9 = 72 MHz SYSCLK/AHB/APB2, APB1 36 MHz (its timers 72 MHz), ADC 12
 * MHz. Sample clock: TIM3 at 1 MHz, one update per sample period. Analog part (ADXL250): TIM3's
 * update (TRGO) starts one ADC1 scan of PA0, PA1 (PA2 for a third axis), 239.5-cycle sampling; DMA1
 * channel 1 moves the codes into a buffer and its transfer-complete interrupt hands the sample
 * over. Duty-cycle part (ADXL202): TIM2 (PA0, x) and TIM4 (PB6, y) in PWM-input mode: a rising edge
 * resets the counter, CCR1 holds the period T2, CCR2 the high time T1; TIM3's update interrupt
 * takes the latest pair of each axis and flags an axis whose output has not toggled for two T2
 * periods (unplugged). Link: USART1 (PA9 TX, PA10 RX) at 921600 baud 8N1, interrupt-driven rings.
 * Time base: SysTick, 1 ms.
 *
 * Missed samples: a sample that arrives while the main loop has not taken the previous one is
 * counted (sample_overrun); the loop predicts over it (app_missed: every axis filter's skip) right
 * after the sample that was waiting, so the filter keeps time. Lost RX bytes (a hardware overrun
 * or a full ring) are counted too; both counters are in every sample frame.
 *
 * Built with ACN_STM32_QEMU (make firmware BOARD=stm32vldiscovery), these sources run on QEMU's
 * stm32vldiscovery machine (STM32F100RB, Cortex-M3, 24 MHz, 128 KiB flash, 8 KiB SRAM). QEMU
 * models its USARTs, the NVIC and SysTick, and nothing else on the bus here: RCC, FLASH, GPIO,
 * TIM2..4, ADC1 and DMA1 are unimplemented devices (writes ignored, reads 0). So that build differs
 * in exactly these places: the clock setup writes its registers but does not wait for HSE and PLL
 * ready flags that never rise; the core clock is the machine's fixed 24 MHz; the sample input is
 * a stimulus feed on USART2 (PA2/PA3, QEMU's second -serial) instead of ADC + DMA or timer
 * capture, polled by the main loop and taken only while the telemetry ring has room (the feed is
 * paced, never dropped); and USART1's transmit ring is emptied by the main loop, not by the TXE
 * interrupt, which QEMU 7.2's USART model never raises (it raises RXNE only), so the loop does not
 * sleep (WFI) either. Startup, vector table, linker-script layout, USART1 receive interrupt and
 * ring, SysTick and the rest of the main loop are the same code. When QEMU's command line names a
 * file feed (emu_feed.h: how PIL runs), the QEMU build takes its input from that file and empties
 * its transmit ring into the other one instead of USART2 and USART1. */
#include "acn_board.h"
#include "stm32_rt.h"
#include "stm32f103_regs.h"
#ifdef ACN_STM32_QEMU
#include "emu_feed.h"
#endif

#ifdef ACN_STM32_QEMU
#define SYSCLK_HZ 24000000u /* QEMU stm32vldiscovery: a fixed sysclk, no RCC model */
/* RCC's ready flags read 0 in QEMU: write the clock setup, do not wait for it */
#define WAIT_UNTIL(cond) ((void)0)
#else
#define SYSCLK_HZ 72000000u
#define WAIT_UNTIL(cond)                                                                           \
    do {                                                                                           \
    } while (!(cond))
#endif
#define BAUD 921600u

#if ACNF_PERIOD_US < 100u || ACNF_PERIOD_US > 65536u
#error "stm32f103: the sample period must be 100 us .. 65.536 ms (TIM3 at 1 MHz, 16 bits)"
#endif
#if ACNF_NAXES > 3 || (ACNF_INPUT_DUTY && ACNF_NAXES > 2)
#error "stm32f103: at most 3 analog axes (PA0..PA2) or 2 duty-cycle axes (TIM2, TIM4)"
#endif

/* ---- time base and samples ---- */
static volatile bool sample_ready;
static volatile uint32_t sample_overrun; /* samples the main loop was too slow to take */
static uint32_t missed_seen;             /* sample_overrun already handed to app_missed */
static acnf_stimulus_t sample;           /* written by the interrupt, read when sample_ready */

static void gpio_mode(gpio_t *port, unsigned pin, uint32_t mode)
{
    REG *cr = pin < 8u ? &port->CRL : &port->CRH;
    unsigned shift = (pin & 7u) * 4u;
    *cr = (*cr & ~(0xfu << shift)) | (mode << shift);
}

static void clock_init(void)
{
    RCC->CR |= RCC_CR_HSEON;
    WAIT_UNTIL(RCC->CR & RCC_CR_HSERDY);
    FLASH->ACR = FLASH_ACR_PRFTBE | FLASH_ACR_LATENCY2; /* 2 wait states above 48 MHz */
    RCC->CFGR = RCC_CFGR_PLLSRC_HSE | RCC_CFGR_PLLMUL9 | RCC_CFGR_PPRE1_DIV2 | RCC_CFGR_ADCPRE_DIV6;
    RCC->CR |= RCC_CR_PLLON;
    WAIT_UNTIL(RCC->CR & RCC_CR_PLLRDY);
    RCC->CFGR |= RCC_CFGR_SW_PLL;
    WAIT_UNTIL((RCC->CFGR & RCC_CFGR_SWS_MASK) == RCC_CFGR_SWS_PLL);
    RCC->AHBENR |= RCC_AHBENR_DMA1EN;
    RCC->APB2ENR |= RCC_APB2ENR_AFIOEN | RCC_APB2ENR_IOPAEN | RCC_APB2ENR_IOPBEN |
                    RCC_APB2ENR_ADC1EN | RCC_APB2ENR_USART1EN;
    RCC->APB1ENR |= RCC_APB1ENR_TIM2EN | RCC_APB1ENR_TIM3EN | RCC_APB1ENR_TIM4EN;
}

static void usart_init(void)
{
    gpio_mode(GPIOA, 9, GPIO_AF_PUSHPULL_50MHZ);
    gpio_mode(GPIOA, 10, GPIO_INPUT_FLOATING);
    USART1->BRR = (SYSCLK_HZ + BAUD / 2u) / BAUD; /* 78: 923077 baud, +0.16 % */
    USART1->CR1 = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE;
    stm32_link_init(USART1);
    nvic_enable(IRQ_USART1);
}

static void sample_clock_init(void)
{
    TIM3->PSC = SYSCLK_HZ / 1000000u - 1u; /* 1 MHz */
    TIM3->ARR = ACNF_PERIOD_US - 1u;
    TIM3->CR2 = TIM_CR2_MMS_UPDATE; /* update -> TRGO (starts the ADC) */
    TIM3->EGR = TIM_EGR_UG;
    TIM3->SR = 0;
}

#if defined(ACN_STM32_QEMU)
static void input_init(void)
{
    RCC->APB1ENR |= RCC_APB1ENR_USART2EN;
    gpio_mode(GPIOA, 2, GPIO_AF_PUSHPULL_50MHZ);              /* USART2 TX */
    gpio_mode(GPIOA, 3, GPIO_INPUT_FLOATING);                 /* USART2 RX */
    USART2->BRR = (SYSCLK_HZ / 2u + BAUD / 2u) / BAUD;        /* APB1 = SYSCLK / 2 */
    USART2->CR1 = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE; /* polled */
}

static bool feed; /* the file feed (emu_feed.h) instead of USART2 and USART1 */

/* The transmit ring as the file feed sees it. */
uint32_t emu_txq_free(void)
{
    return stm32_link_tx_free();
}

bool emu_txq_next(uint8_t *b)
{
    return stm32_link_tx_next(b);
}

/* One stimulus byte, when there is one and the telemetry ring has room for what it may produce:
 * QEMU's USART takes the next byte from its socket only after DR is read, so the feed waits. */
static void stim_poll(void)
{
    if ((USART2->SR & USART_SR_RXNE) && stm32_link_tx_free() >= 3u * ACNF_MAX_UP_WIRE) {
        uint8_t b = (uint8_t)USART2->DR;
        app_rx(APP_CH_STIM, &b, 1);
    }
}
#elif !ACNF_INPUT_DUTY
static volatile uint16_t adc_codes[ACNF_NAXES]; /* DMA target */

static void input_init(void)
{
    unsigned i;
    uint32_t sqr3 = 0;
    for (i = 0; i < ACNF_NAXES; ++i) {
        gpio_mode(GPIOA, i, GPIO_ANALOG);
        sqr3 |= (uint32_t)i << (5u * i); /* rank i+1 converts channel i */
    }
    ADC1->CR2 = ADC_CR2_ADON; /* power up, then calibrate */
    for (i = 0; i < 1000u; ++i) {
        __asm__ volatile("nop");
    }
    ADC1->CR2 |= ADC_CR2_RSTCAL;
    while (ADC1->CR2 & ADC_CR2_RSTCAL) {
    }
    ADC1->CR2 |= ADC_CR2_CAL;
    while (ADC1->CR2 & ADC_CR2_CAL) {
    }
    ADC1->SMPR2 = 0x3fffffffu; /* 239.5 cycles on channels 0..9: the sensor's RC output is slow */
    ADC1->SQR1 = (uint32_t)(ACNF_NAXES - 1) << 20;
    ADC1->SQR3 = sqr3;
    ADC1->CR1 = ADC_CR1_SCAN;
    ADC1->CR2 = ADC_CR2_ADON | ADC_CR2_DMA | ADC_CR2_EXTSEL_TIM3_TRGO | ADC_CR2_EXTTRIG;

    DMA1->CH[0].CPAR = (uint32_t)&ADC1->DR;
    DMA1->CH[0].CMAR = (uint32_t)adc_codes;
    DMA1->CH[0].CNDTR = ACNF_NAXES;
    DMA1->CH[0].CCR =
        DMA_CCR_MINC | DMA_CCR_PSIZE16 | DMA_CCR_MSIZE16 | DMA_CCR_CIRC | DMA_CCR_TCIE | DMA_CCR_EN;
    nvic_enable(IRQ_DMA1_CH1);
    TIM3->CR1 = TIM_CR1_CEN;
}

void dma1_ch1_handler(void)
{
    unsigned i;
    DMA1->IFCR = DMA_IFCR_CGIF1;
    if (sample_ready) {
        ++sample_overrun;
        return;
    }
    sample.flags = 0;
    for (i = 0; i < ACNF_NAXES; ++i) {
        sample.code[i] = adc_codes[i];
    }
    sample_ready = true;
}
#else
#if (SYSCLK_HZ % ACNF_TIMER_HZ) != 0u || SYSCLK_HZ / ACNF_TIMER_HZ > 65536u
#error "stm32f103: the model's duty-cycle timer clock must divide 72 MHz"
#endif
#if ACNF_T2_NOMINAL * 5u / 4u > 65535u
#error "stm32f103: the duty-cycle period (+25 %) must fit the 16-bit capture timers"
#endif
/* no capture for this many sample periods: at least two T2 periods */
#define T2_US ((uint32_t)((uint64_t)ACNF_T2_NOMINAL * 1000000u / ACNF_TIMER_HZ))
#define TIMEOUT_TICKS ((2u * T2_US + ACNF_PERIOD_US - 1u) / ACNF_PERIOD_US)

static tim_t *const cap_tim[2] = {TIM2, TIM4};
static volatile uint32_t cap_t1[2], cap_t2[2], cap_count[2];
static uint32_t cap_seen[2], cap_idle[2];

static void capture_init(tim_t *t)
{
    t->PSC = SYSCLK_HZ / ACNF_TIMER_HZ - 1u;
    t->ARR = 0xffffu;
    t->CCMR1 = TIM_CCMR1_CC1S_TI1 | TIM_CCMR1_CC2S_TI1;      /* both channels see TI1 */
    t->CCER = TIM_CCER_CC1E | TIM_CCER_CC2E | TIM_CCER_CC2P; /* CC1 rising, CC2 falling */
    t->SMCR = TIM_SMCR_TS_TI1FP1 | TIM_SMCR_SMS_RESET;       /* a rising edge restarts the count */
    t->DIER = TIM_DIER_CC1IE;
    t->EGR = TIM_EGR_UG;
    t->SR = 0;
    t->CR1 = TIM_CR1_CEN;
}

static void input_init(void)
{
    gpio_mode(GPIOA, 0, GPIO_INPUT_FLOATING); /* TIM2_CH1 */
    gpio_mode(GPIOB, 6, GPIO_INPUT_FLOATING); /* TIM4_CH1 */
    capture_init(TIM2);
    nvic_enable(IRQ_TIM2);
    if (ACNF_NAXES > 1) {
        capture_init(TIM4);
        nvic_enable(IRQ_TIM4);
    }
    TIM3->DIER = TIM_DIER_UIE;
    nvic_enable(IRQ_TIM3);
    TIM3->CR1 = TIM_CR1_CEN;
}

static void capture_irq(unsigned axis)
{
    tim_t *t = cap_tim[axis];
    if (t->SR & TIM_SR_CC1IF) {
        cap_t2[axis] = t->CCR1; /* reading CCR1 clears CC1IF */
        cap_t1[axis] = t->CCR2;
        ++cap_count[axis];
    }
    t->SR = ~TIM_SR_CC1OF;
}

void tim2_handler(void)
{
    capture_irq(0);
}

void tim4_handler(void)
{
    capture_irq(1);
}

void tim3_handler(void)
{
    unsigned i;
    TIM3->SR = ~TIM_SR_UIF;
    if (sample_ready) {
        ++sample_overrun;
        return;
    }
    sample.flags = 0;
    for (i = 0; i < ACNF_NAXES; ++i) {
        uint32_t c = cap_count[i];
        cap_idle[i] = (c == cap_seen[i]) ? cap_idle[i] + 1u : 0u;
        cap_seen[i] = c;
        sample.t1[i] = cap_t1[i];
        sample.t2[i] = cap_t2[i];
        if (cap_idle[i] >= TIMEOUT_TICKS) {
            sample.flags |= (uint8_t)(1u << i);
        }
    }
    sample_ready = true;
}
#endif

void board_init(void)
{
    clock_init();
    stm32_time_init(SYSCLK_HZ);
    usart_init();
    sample_clock_init();
    input_init();
#ifdef ACN_STM32_QEMU
    feed = emu_feed_start();
#endif
}

uint8_t board_id(void)
{
#ifdef ACN_STM32_QEMU
    return ACNF_BOARD_STM32VLDISCOVERY;
#else
    return ACNF_BOARD_STM32F103;
#endif
}

bool board_poll(void)
{
    uint8_t b;
#ifdef ACN_STM32_QEMU
    if (feed) {
        emu_feed_poll();
        return true;
    }
#endif
    if (sample_ready) {
        acnf_stimulus_t in;
        uint32_t overrun;
        irq_disable();
        in = sample;
        overrun = sample_overrun; /* the samples that came while this one waited */
        sample_ready = false;
        irq_enable();
        app_sample(&in);
        app_missed(overrun - missed_seen); /* predict over them, in order, after it */
        missed_seen = overrun;
    }
    while (stm32_link_rx(&b)) {
        app_rx(APP_CH_HOST, &b, 1);
    }
#ifdef ACN_STM32_QEMU
    stm32_link_tx_poll();
    stim_poll();
#else
    irq_disable();
    if (!sample_ready && stm32_link_rx_empty()) {
        __asm__ volatile("wfi"); /* an interrupt wakes it even with interrupts masked */
    }
    irq_enable();
#endif
    return true;
}
