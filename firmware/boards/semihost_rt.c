/* The shared bare-metal runtime of the emulated boards: see semihost_rt.h. */
#include "semihost_rt.h"

#include "semihost.h"

extern uint32_t __data_start, __data_end, __data_load, __bss_start, __bss_end;

void board_puts(const char *s)
{
    semihost_call(SEMIHOST_SYS_WRITE0, s);
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
    semihost_call(SEMIHOST_SYS_EXIT,
                  (const void *)(status == 0 ? SEMIHOST_EXIT_OK : SEMIHOST_EXIT_ERROR));
    for (;;) {
    }
}

#if defined(__riscv)
/* RV32 (sifive_e) has no SysTick: the CLINT's mtime, free-running on its own clock (board.h's
 * BOARD_TICK_HZ), read as the same 24-bit count so that emu_txq.c folds it the same way. */
#define CLINT_MTIME (*(volatile uint32_t *)0x0200BFF8u)

void board_ticks_start(void) {}

uint32_t board_ticks(void)
{
    return CLINT_MTIME & 0x00FFFFFFu;
}
#else
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
#endif

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
