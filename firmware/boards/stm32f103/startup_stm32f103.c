/* Reset handler and vector table of the STM32F103C8 (medium density, 43 IRQs).
 * The initial stack pointer is the first word of .isr_vector, put there by the
 * linker script; this table starts at the reset vector. */
#include <stdint.h>

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss;
int main(void);

void reset_handler(void);
void default_handler(void);

void default_handler(void)
{
    for (;;) { /* an unexpected interrupt or fault: stop here for the debugger */
    }
}

#define WEAK_HANDLER(name) void name(void) __attribute__((weak, alias("default_handler")))
WEAK_HANDLER(nmi_handler);
WEAK_HANDLER(hardfault_handler);
WEAK_HANDLER(memmanage_handler);
WEAK_HANDLER(busfault_handler);
WEAK_HANDLER(usagefault_handler);
WEAK_HANDLER(svc_handler);
WEAK_HANDLER(pendsv_handler);
WEAK_HANDLER(systick_handler);
WEAK_HANDLER(dma1_ch1_handler);
WEAK_HANDLER(tim2_handler);
WEAK_HANDLER(tim3_handler);
WEAK_HANDLER(tim4_handler);
WEAK_HANDLER(usart1_handler);

typedef void (*vector_t)(void);

/* exceptions 1..15, then IRQ 0..42 */
__attribute__((section(".isr_vector"), used)) static const vector_t vectors[15 + 43] = {
    reset_handler,
    nmi_handler,
    hardfault_handler,
    memmanage_handler,
    busfault_handler,
    usagefault_handler,
    0,
    0,
    0,
    0,
    svc_handler,
    0,
    0,
    pendsv_handler,
    systick_handler,
    [15 + 11] = dma1_ch1_handler,
    [15 + 28] = tim2_handler,
    [15 + 29] = tim3_handler,
    [15 + 30] = tim4_handler,
    [15 + 37] = usart1_handler,
};

void reset_handler(void)
{
    uint32_t *src = &_sidata;
    uint32_t *dst;
    for (dst = &_sdata; dst < &_edata;) {
        *dst++ = *src++;
    }
    for (dst = &_sbss; dst < &_ebss;) {
        *dst++ = 0;
    }
    (void)main();
    for (;;) {
    }
}
