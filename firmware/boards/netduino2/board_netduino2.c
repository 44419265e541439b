/* accelnav board layer for QEMU's netduino2 (STM32F205, Cortex-M3): the board whose sampling path
 * runs on modelled peripherals. TIM3 makes the sample clock (update interrupt once a period); its
 * handler converts each axis on ADC1 (PA0, PA1, PA2: one software-started conversion a channel,
 * 144-cycle sampling, the resolution the model's ADC has) and hands the codes to the main loop,
 * which runs the filters and streams the telemetry on USART1 (PA9 TX, PA10 RX, 921600 baud 8N1).
 * Commands come in on USART1 too. Time base: SysTick, 1 ms. Missed samples (the main loop had not
 * taken the last one) and lost RX bytes are counted as on the stm32f103 port.
 *
 * QEMU 7.2 models on this machine the core, NVIC, SysTick, the USARTs, TIM2..5 and ADC1..3, not
 * RCC, FLASH or GPIO (their accesses are refused: reads 0, writes dropped). Where the emulation
 * differs from the part, and what this build (ACN_STM32_QEMU, always set for BOARD=netduino2) does:
 *  - the clock setup is written but its ready flags, which never rise, are not waited for; the core
 *    runs at the machine's 120 MHz, which is the part's PLL setting here anyway;
 *  - QEMU clocks the timers at a fixed 1 GHz (the part: 60 MHz at APB1 = 30 MHz), so TIM3's
 *    prescaler differs; its period is ARR counts there, ARR + 1 on the part (0.1 % short at 1 kHz);
 *  - QEMU's ADC never sets EOC: the conversion is not waited for; its DR read, after SWSTART with
 *    ADON, returns the previous value + 7 (masked to the resolution), whatever the channel;
 *  - the USART raises no TXE interrupt, so the main loop moves the transmit ring itself
 *    (stm32_rt.h: the link and time base of the stm32f103 port).
 * The run length is given on QEMU's semihosting command line, `accelnav-adc N [CMDS]`: N sample
 * periods, then the transmit ring is emptied and the emulator exits (SYS_EXIT); CMDS, a file of
 * command frames, goes to the command receiver before the sample clock starts. Without that command
 * line the board samples and streams for ever. QEMU must be started with semihosting on. */
#include "acn_board.h"
#include "semihost.h"
#include "stm32_rt.h"
#include "stm32f2_regs.h"

#define SYSCLK_HZ 120000000u /* HSI 16 MHz / 16 x 240 / 2; QEMU's netduino2: a fixed 120 MHz */
#define APB2_HZ (SYSCLK_HZ / 2u)
#ifdef ACN_STM32_QEMU
#define TIMCLK_HZ 1000000000u      /* QEMU 7.2 clocks TIM2..5 at 1 GHz, whatever RCC says */
#define WAIT_UNTIL(cond) ((void)0) /* RCC's ready flags and the ADC's EOC never rise in QEMU */
#else
#define TIMCLK_HZ (2u * (SYSCLK_HZ / 4u)) /* APB1 = SYSCLK / 4; its timers run at twice that */
#define WAIT_UNTIL(cond)                                                                           \
    do {                                                                                           \
    } while (!(cond))
#endif
#define BAUD 921600u

#if ACNF_INPUT_DUTY
#error "netduino2: an analog (ADC) model only; the duty-cycle input runs on the other boards"
#endif
#if ACNF_NAXES > 3
#error "netduino2: at most 3 analog axes (PA0..PA2)"
#endif
#if ACNF_PERIOD_US < 100u || ACNF_PERIOD_US > 65536u
#error "netduino2: the sample period must be 100 us .. 65.536 ms (TIM3 at 1 MHz, 16 bits)"
#endif
/* the F2's ADC resolutions: 12, 10, 8 or 6 bits (CR1.RES 0..3) */
#if ACNF_FULL_CODE == 4095
#define ADC_RES 0u
#elif ACNF_FULL_CODE == 1023
#define ADC_RES 1u
#elif ACNF_FULL_CODE == 255
#define ADC_RES 2u
#elif ACNF_FULL_CODE == 63
#define ADC_RES 3u
#else
#error                                                                                             \
    "netduino2: the STM32F2's ADC converts 12, 10, 8 or 6 bits; the model's ADC has another width"
#endif

/* ---- time base and samples ---- */
static volatile bool sample_ready;
static volatile uint32_t sample_overrun;
static uint32_t missed_seen;
static acnf_stimulus_t sample;

static bool started; /* the sample clock runs */

#ifdef ACN_STM32_QEMU /* ---- the emulator's run (semihosting command line) ---- */
#define MARKER "accelnav-adc "
static char cmdline[128];
static uint32_t run_periods; /* 0: sample for ever */
static uint32_t periods_done;
static const char *cmd_file; /* command frames to take before sampling, or none */
#endif

static void gpio_mode(gpio_t *port, unsigned pin, uint32_t mode, uint32_t af)
{
    port->MODER = (port->MODER & ~(3u << (2u * pin))) | (mode << (2u * pin));
    port->AFR[pin >> 3] =
        (port->AFR[pin >> 3] & ~(0xfu << (4u * (pin & 7u)))) | (af << (4u * (pin & 7u)));
}

static void clock_init(void)
{
    RCC->CR |= RCC_CR_HSION;
    WAIT_UNTIL(RCC->CR & RCC_CR_HSIRDY);
    /* 3 wait states from 90 MHz at 2.7..3.6 V; prefetch and caches on */
    FLASH->ACR = FLASH_ACR_LATENCY3 | FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN;
    RCC->PLLCFGR = RCC_PLLCFGR(16u, 240u, 2u, 5u); /* HSI / 16 x 240 = 240 MHz VCO; / 2, / 5 (48) */
    RCC->CFGR = RCC_CFGR_PPRE1_DIV4 | RCC_CFGR_PPRE2_DIV2;
    RCC->CR |= RCC_CR_PLLON;
    WAIT_UNTIL(RCC->CR & RCC_CR_PLLRDY);
    RCC->CFGR |= RCC_CFGR_SW_PLL;
    WAIT_UNTIL((RCC->CFGR & RCC_CFGR_SWS_MASK) == RCC_CFGR_SWS_PLL);
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIOAEN;
    RCC->APB1ENR |= RCC_APB1ENR_TIM3EN;
    RCC->APB2ENR |= RCC_APB2ENR_USART1EN | RCC_APB2ENR_ADC1EN;
}

static void usart_init(void)
{
    gpio_mode(GPIOA, 9, GPIO_MODE_AF, GPIO_AF_USART1);
    gpio_mode(GPIOA, 10, GPIO_MODE_AF, GPIO_AF_USART1);
    USART1->BRR = (APB2_HZ + BAUD / 2u) / BAUD; /* 65: 923077 baud, +0.16 % */
    USART1->CR1 = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE;
    stm32_link_init(USART1);
    nvic_enable(IRQ_USART1);
}

static void adc_init(void)
{
    unsigned i;
    for (i = 0; i < ACNF_NAXES; ++i) {
        gpio_mode(GPIOA, i, GPIO_MODE_ANALOG, 0u);
    }
    *ADC_CCR = ADC_CCR_ADCPRE_DIV4; /* 60 / 4 = 15 MHz (at most 30 MHz) */
    ADC1->SMPR2 = 06666u;           /* 144 cycles on channels 0..3: a slow RC source */
    ADC1->CR1 = ADC_RES << ADC_CR1_RES_SHIFT;
    ADC1->SQR1 = 0;           /* one conversion a start: the channel in SQR3 */
    ADC1->CR2 = ADC_CR2_ADON; /* powered up long before the first sample (tSTAB 3 us) */
}

static void sample_clock_init(void)
{
    TIM3->PSC = TIMCLK_HZ / 1000000u - 1u; /* 1 MHz */
    TIM3->ARR = ACNF_PERIOD_US - 1u;
    TIM3->EGR = TIM_EGR_UG; /* load the prescaler */
    TIM3->SR = 0;
    TIM3->DIER = TIM_DIER_UIE;
    nvic_enable(IRQ_TIM3);
}

/* One sample: each axis converted in turn, its code read from DR. */
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
        ADC1->SQR3 = i; /* channel i (PAi) */
        ADC1->CR2 = ADC_CR2_ADON | ADC_CR2_SWSTART;
        WAIT_UNTIL(ADC1->SR & ADC_SR_EOC);
        sample.code[i] = (uint16_t)ADC1->DR; /* reading DR clears EOC */
    }
    sample_ready = true;
}

#ifdef ACN_STM32_QEMU
static void board_exit(uint32_t status, const char *why)
{
    if (why) {
        semihost_call(SEMIHOST_SYS_WRITE0, why);
    }
    semihost_call(SEMIHOST_SYS_EXIT, (const void *)status);
    for (;;) {
    }
}

/* `accelnav-adc N [CMDS]` on the semihosting command line: the run's length and command file. */
static void run_args(void)
{
    uint32_t args[2], i;
    char *p;
    args[0] = (uint32_t)cmdline;
    args[1] = sizeof cmdline - 1u;
    if (semihost_call(SEMIHOST_SYS_GET_CMDLINE, args) != 0) {
        return;
    }
    for (i = 0; i < sizeof MARKER - 1u; ++i) {
        if (cmdline[i] != MARKER[i]) {
            return; /* not an accelnav run: sample for ever */
        }
    }
    p = &cmdline[sizeof MARKER - 1u];
    for (; *p >= '0' && *p <= '9' && run_periods < 100000000u; ++p) {
        run_periods = run_periods * 10u + (uint32_t)(*p - '0');
    }
    if (run_periods == 0u || (*p != '\0' && *p != ' ')) {
        board_exit(SEMIHOST_EXIT_ERROR, "accelnav-adc: expected a sample count 1..100000000\n");
    }
    while (*p == ' ') {
        ++p;
    }
    cmd_file = *p != '\0' ? p : 0;
}

/* The command file, every byte to the command receiver, the answers sent as they come. */
static void take_commands(void)
{
    uint32_t args[3], n, i;
    int fd, left;
    uint8_t buf[64];
    args[0] = (uint32_t)cmd_file;
    args[1] = 1u; /* "rb" */
    for (n = 0; cmd_file[n] != '\0'; ++n) {
    }
    args[2] = n;
    fd = semihost_call(SEMIHOST_SYS_OPEN, args);
    if (fd < 0) {
        board_exit(SEMIHOST_EXIT_ERROR, "accelnav-adc: cannot open the command file\n");
    }
    do {
        args[0] = (uint32_t)fd;
        args[1] = (uint32_t)buf;
        args[2] = sizeof buf;
        left = semihost_call(SEMIHOST_SYS_READ, args); /* the count of bytes not read */
        if (left < 0 || left > (int)sizeof buf) {
            board_exit(SEMIHOST_EXIT_ERROR, "accelnav-adc: cannot read the command file\n");
        }
        for (i = 0; i < sizeof buf - (uint32_t)left; ++i) {
            while (stm32_link_tx_free() < 3u * ACNF_MAX_UP_WIRE) {
                stm32_link_tx_poll(); /* room for what a command may answer */
            }
            app_rx(APP_CH_HOST, &buf[i], 1);
        }
    } while (left == 0);
    semihost_call(SEMIHOST_SYS_CLOSE, &fd);
}
#endif

void board_init(void)
{
    clock_init();
    stm32_time_init(SYSCLK_HZ);
    usart_init();
    adc_init();
    sample_clock_init();
#ifdef ACN_STM32_QEMU
    run_args();
#endif
}

uint8_t board_id(void)
{
    return ACNF_BOARD_NETDUINO2;
}

bool board_poll(void)
{
    uint8_t b;
    if (!started) { /* after app_init: the commands, then the sample clock */
        started = true;
#ifdef ACN_STM32_QEMU
        if (cmd_file) {
            take_commands();
        }
#endif
        TIM3->CR1 = TIM_CR1_CEN;
    }
    if (sample_ready) {
        acnf_stimulus_t in;
        uint32_t overrun;
        irq_disable();
        in = sample;
        overrun = sample_overrun;
        sample_ready = false;
        irq_enable();
        app_sample(&in);
        app_missed(overrun - missed_seen);
#ifdef ACN_STM32_QEMU
        periods_done += 1u + (overrun - missed_seen);
        missed_seen = overrun;
        if (run_periods != 0u && periods_done >= run_periods) {
            TIM3->CR1 = 0; /* the run is over: send what is queued, then end the emulator */
            while (!stm32_link_tx_empty()) {
                stm32_link_tx_poll();
            }
            board_exit(SEMIHOST_EXIT_OK, 0);
        }
#else
        missed_seen = overrun;
#endif
    }
    while (stm32_link_rx(&b)) {
        app_rx(APP_CH_HOST, &b, 1);
    }
#ifdef ACN_STM32_QEMU
    stm32_link_tx_poll();
#endif
    irq_disable();
    if (!sample_ready && stm32_link_rx_empty()) {
        __asm__ volatile("wfi"); /* an interrupt wakes it even with interrupts masked */
    }
    irq_enable();
    return true;
}
