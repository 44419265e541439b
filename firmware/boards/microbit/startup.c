/* Vector table of QEMU microbit (nRF51822); the runtime itself is ../semihost_rt.c. */
#include "board.h"

extern uint32_t __stack_top;

__attribute__((section(".vectors"), used)) static const void *const vectors[16] = {
    &__stack_top,        /* initial SP */
    (void *)board_reset, /* reset */
    (void *)board_fault, /* NMI */
    (void *)board_fault, /* HardFault (the M0 has no MemManage, BusFault, UsageFault) */
};
