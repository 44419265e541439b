/* The shared bare-metal runtime of the emulated boards: see semihost_rt.h. */
#include "semihost_rt.h"

extern uint32_t __data_start, __data_end, __data_load, __bss_start, __bss_end;

static int semihost(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

void board_puts(const char *s)
{
    semihost(0x04, s); /* SYS_WRITE0 */
}

void board_put_u32(uint32_t v)
{
    char buf[11];
    int i = 10;
    buf[i] = '\0';
    do {
        buf[--i] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v);
    board_puts(&buf[i]);
}

void board_exit(int status)
{
    /* SYS_EXIT with ADP_Stopped_ApplicationExit (0x20026) or RunTimeErrorUnknown (0x20023) */
    semihost(0x18, (const void *)(status == 0 ? 0x20026u : 0x20023u));
    for (;;) {
    }
}

#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)

void board_ticks_start(void)
{
    SYST_CSR = 0;
    SYST_RVR = 0x00FFFFFFu;
    SYST_CVR = 0;
    SYST_CSR = 5u; /* enable, core clock, no interrupt */
}

uint32_t board_ticks(void)
{
    return (0x00FFFFFFu - SYST_CVR) & 0x00FFFFFFu;
}

uint32_t board_ticks_since(uint32_t t0)
{
    return (board_ticks() - t0) & 0x00FFFFFFu;
}

void board_fault(void)
{
    board_puts("fault\n");
    board_exit(1);
}

void board_reset(void)
{
    uint32_t *src = &__data_load;
    uint32_t *dst;
    for (dst = &__data_start; dst < &__data_end;) {
        *dst++ = *src++;
    }
    for (dst = &__bss_start; dst < &__bss_end;) {
        *dst++ = 0;
    }
    board_exit(main());
}
