/* Reset entry and trap vector of QEMU sifive_e; the runtime itself is ../semihost_rt.c.
 *
 * The mask ROM jumps to the start of the HiFive1's program flash (0x20400000), where the linker
 * script puts _start: set the global and stack pointers, point mtvec at the trap entry (any trap is
 * a fault: nothing here enables interrupts), then the shared board_reset (.data, .bss, main). */
#include "board.h"

__asm__(".section .text.start, \"ax\", @progbits\n"
        ".globl _start\n"
        "_start:\n"
        ".option push\n"
        ".option norelax\n"
        "    la gp, __global_pointer$\n"
        ".option pop\n"
        "    la sp, __stack_top\n"
        "    la t0, acn_trap\n"
        ".option push\n"
        ".option arch, +zicsr\n"
        "    csrw mtvec, t0\n"
        ".option pop\n"
        "    j board_reset\n"
        ".balign 4\n" /* mtvec's direct mode needs a 4-byte aligned entry */
        "acn_trap:\n"
        "    j board_fault\n");
