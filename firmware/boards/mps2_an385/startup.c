/* Vector table and UART0 output of QEMU mps2-an385; the runtime itself is ../semihost_rt.c. */
#include "board.h"

extern uint32_t __stack_top;

__attribute__((section(".vectors"), used)) static const void *const vectors[16] = {
    &__stack_top,        /* initial SP */
    (void *)board_reset, /* reset */
    (void *)board_fault, /* NMI */
    (void *)board_fault, /* HardFault */
    (void *)board_fault, /* MemManage */
    (void *)board_fault, /* BusFault */
    (void *)board_fault, /* UsageFault */
};

void board_uart_puts(const char *s)
{
    volatile uint32_t *uart = (volatile uint32_t *)0x40004000u;
    uart[2] = 1u; /* CTRL: TX enable */
    while (*s) {
        while (uart[1] & 1u) { /* STATE: TX full */
        }
        uart[0] = (uint32_t)(unsigned char)*s++;
    }
}
