/* The semihosting trap (ARM: bkpt 0xab; RISC-V: the ebreak sequence; QEMU started with
 * -semihosting) and the operation numbers the emulated boards use: one definition for the shared
 * runtime (semihost_rt.c) and the file feed (emu_feed.c), which the stm32vldiscovery build links
 * without that runtime. */
#ifndef SEMIHOST_H
#define SEMIHOST_H

#include <stdint.h>

#define SEMIHOST_SYS_OPEN 0x01
#define SEMIHOST_SYS_CLOSE 0x02
#define SEMIHOST_SYS_WRITE0 0x04
#define SEMIHOST_SYS_WRITE 0x05
#define SEMIHOST_SYS_READ 0x06
#define SEMIHOST_SYS_GET_CMDLINE 0x15
#define SEMIHOST_SYS_EXIT 0x18
#define SEMIHOST_EXIT_OK 0x20026u    /* ADP_Stopped_ApplicationExit */
#define SEMIHOST_EXIT_ERROR 0x20023u /* ADP_Stopped_RunTimeErrorUnknown */

#if defined(__riscv)
/* RISC-V semihosting (sifive_e): op in a0, arg in a1, the result in a0. The debugger knows the trap
 * by the uncompressed three-instruction sequence around ebreak, so it must not be compressed
 * (norvc) and is kept 16-byte aligned, inside one page. The alignment comes before norvc: under
 * norvc the assembler reserves too little padding for the linker's relaxation to align the
 * sequence, and the link fails ("bytes required for alignment") where the code before it ends on
 * 2 bytes. */
static inline int semihost_call(int op, const void *arg)
{
    register int a0 __asm__("a0") = op;
    register const void *a1 __asm__("a1") = arg;
    __asm__ volatile(".option push\n.balign 16\n.option norvc\n"
                     "slli x0, x0, 0x1f\nebreak\nsrai x0, x0, 7\n.option pop"
                     : "+r"(a0)
                     : "r"(a1)
                     : "memory");
    return a0;
}
#else
/* Operation op with its argument block (or value) arg; returns r0. */
static inline int semihost_call(int op, const void *arg)
{
    register int r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}
#endif

#endif
