/* acn_runtime.h: the fixed-point runtime every generated filter (PREFIX.c) carries.
 *
 * The generator (accelnav.codegen.emit_c) copies the text between the two clang-format
 * markers below into every generated .c byte for byte, so that a filter builds from its own
 * files alone and regenerating gives an empty diff. That text keeps the generated C's layout
 * (120 columns), which is why clang-format leaves it alone. The header also compiles on its
 * own with the strict flags (tests/codegen/test_runtime_header.py). */
#ifndef ACN_RUNTIME_H
#define ACN_RUNTIME_H

#include <limits.h> /* UINT_MAX: acn_clz32 */
#include <stdbool.h>
#include <stddef.h> /* offsetof */
#include <stdint.h>
#if defined(__AVR__)
#include <avr/pgmspace.h> /* PROGMEM, pgm_read_*: the tables in flash */
#endif

/* clang-format off */

/* Constant tables the filter only reads: in flash on AVR (its .rodata would be copied into the few
 * KiB of RAM at start, leaving less for the state and the stack), read through pgm_read_*; plain
 * const arrays everywhere else. */
#if defined(__AVR__) /* <avr/pgmspace.h> is included with the other headers, above */
#define ACN_ROM PROGMEM
#define ACN_ROM_U16(p) ((uint16_t)pgm_read_word(p))
#define ACN_ROM_U32(p) ((uint32_t)pgm_read_dword(p))
#define ACN_ROM_I32(p) ((int32_t)pgm_read_dword(p))
#define ACN_ROM_U8(p) ((uint8_t)pgm_read_byte(p))
/* little-endian: the low word first */
#define ACN_ROM_I64(p)                                                                             \
    ((int64_t)((uint64_t)pgm_read_dword((const uint8_t *)(p) + 4) << 32 | pgm_read_dword(p)))
/* two 32-bit fields of a gain-schedule row, as ACN_LD2 (below) reads them from RAM */
#define ACN_SEG2(a, b, base, T, f1, f2) ((a) = ACN_ROM_U32(&(base)->f1), (b) = ACN_ROM_U32(&(base)->f2))
#else
#define ACN_ROM
#define ACN_ROM_U16(p) (*(p))
#define ACN_ROM_U32(p) (*(p))
#define ACN_ROM_I32(p) (*(p))
#define ACN_ROM_U8(p) (*(p))
#define ACN_ROM_I64(p) (*(p))
#define ACN_SEG2(a, b, base, T, f1, f2) ACN_LD2(a, b, base, T, f1, f2)
#endif
/* The per-sample core is inlined into each entry point (it is small, and a call costs a register
 * save and restore every sample). */
#if defined(__GNUC__)
#define ACN_INLINE static inline __attribute__((always_inline))
#else
#define ACN_INLINE static inline
#endif
/* The covariance form's core: inlined too, but on AVR one copy that update and step call (a copy is
 * kilobytes there; the call is some 40 cycles of a step's thousands). */
#if defined(__AVR__) && defined(__GNUC__)
#define ACN_CORE static __attribute__((noinline))
#else
#define ACN_CORE ACN_INLINE
#endif
/* Two adjacent 32-bit fields f1, f2 of *base (f2 four bytes after f1, checked at compile time) in one
 * LDRD (STRD): gcc for Cortex-M3 moves them one word at a time. Word by word, so the same values on
 * any endianness; elsewhere (and with clang, whose operand modifiers are not checked here) plain member
 * accesses. */
#if defined(__arm__) && defined(__thumb2__) && !defined(__clang__)
#define ACN_ADJ(T, f1, f2) ((void)sizeof(char[offsetof(T, f2) == offsetof(T, f1) + 4 ? 1 : -1]))
#define ACN_LD2(a, b, base, T, f1, f2)                                                                   \
    do {                                                                                                \
        ACN_ADJ(T, f1, f2);                                                                             \
        __asm__("ldrd %0, %1, [%2, #%c3]"                                                               \
                : "=r"(a), "=r"(b)                                                                      \
                : "r"(base), "i"(offsetof(T, f1)), "m"(*(const char(*)[8])(const void *)&(base)->f1));  \
    } while (0)
#define ACN_ST2(a, b, base, T, f1, f2)                                                                   \
    do {                                                                                                \
        ACN_ADJ(T, f1, f2);                                                                             \
        __asm__("strd %1, %2, [%3, #%c4]"                                                               \
                : "=m"(*(char(*)[8])(void *)&(base)->f1)                                                \
                : "r"(a), "r"(b), "r"(base), "i"(offsetof(T, f1)));                                     \
    } while (0)
/* An int64 field f of *base in one LDRD, as its low and high word (little-endian only) */
#if defined(__ARM_BIG_ENDIAN)
#define ACN_LD64(lo, hi, base, T, f) ((lo) = (uint32_t)(base)->f, (hi) = (uint32_t)((uint64_t)(base)->f >> 32))
#define ACN_ST64(x, base, T, f) ((base)->f = (x))
#else
#define ACN_LD64(lo, hi, base, T, f)                                                                     \
    __asm__("ldrd %0, %1, [%2, #%c3]"                                                                   \
            : "=r"(lo), "=r"(hi)                                                                        \
            : "r"(base), "i"(offsetof(T, f)), "m"(*(const char(*)[8])(const void *)&(base)->f))
#define ACN_ST64(x, base, T, f)                                                                          \
    __asm__("strd %1, %2, [%3, #%c4]"                                                                   \
            : "=m"(*(char(*)[8])(void *)&(base)->f)                                                     \
            : "r"((uint32_t)(x)), "r"((uint32_t)((uint64_t)(x) >> 32)), "r"(base), "i"(offsetof(T, f)))
#endif
#else
#define ACN_LD2(a, b, base, T, f1, f2) ((a) = (uint32_t)(base)->f1, (b) = (uint32_t)(base)->f2)
#define ACN_ST2(a, b, base, T, f1, f2) ((base)->f1 = (a), (base)->f2 = (b))
#define ACN_LD64(lo, hi, base, T, f) ((lo) = (uint32_t)(base)->f, (hi) = (uint32_t)((uint64_t)(base)->f >> 32))
#define ACN_ST64(x, base, T, f) ((base)->f = (x))
#endif

/* Round-to-nearest right shift of an int64 by s >= 1 (ties toward +inf). The
 * right shift of a negative value is arithmetic on every compiler accelnav
 * supports (gcc, clang, arm-none-eabi-gcc); it is checked in the tests. */
#define ACN_RSHR(x, s) (((x) + ((int64_t)1 << ((s) - 1))) >> (s))

/* AVR: avr-gcc spends 64-bit arithmetic in libgcc calls whose fixed registers cost more moves than the
 * work (a 32x32 -> 64 multiply-add was __mulsidi3, __adddi3 and some 30 register copies; even x >> 32
 * called __ashrdi3). The products, high words and rounded shifts of the filter go through three small
 * routines instead, one copy for every filter in the image (weak symbols), written for avr-gcc's calling
 * convention: an int64 in r18..r25 (byte k in r18 + k), then an int32 in r14..r17 and one in r10..r13
 * (kept by the routine, as the convention wants), a byte count in r16; an int64 comes back in r18..r25,
 * an int32 in r22..r25: the high word of the int64 left there, so "the high word of acc + a b" is the
 * same routine declared with an int32 result. The same integers as the C below (the tests compare the
 * images with the host's byte for byte). */
#if defined(__AVR__) && defined(__GNUC__) && !defined(ACN_PLAIN_AVR)
#define ACN_AVR_ASM 1
#define ACN_MATH static inline __attribute__((always_inline)) /* a call into the routines, nothing around it */
int64_t acn_avr_smac(int64_t acc, int32_t a, int32_t b);                          /* acc + a b */
int32_t acn_avr_smac_hi(int64_t acc, int32_t a, int32_t b) __asm__("acn_avr_smac"); /* its high word */
int32_t acn_avr_umac_hi(int64_t acc, uint32_t a, uint32_t b) __asm__("acn_avr_umac"); /* unsigned */
uint64_t acn_avr_umac(uint64_t acc, uint32_t a, uint32_t b); /* acc + a b, unsigned */
int32_t acn_avr_rshr32(int64_t x, uint8_t s); /* the low word of (x + 2^(s-1)) >> s, 1 <= s <= 63 */
int32_t acn_avr_hi_round(int64_t x);          /* the high word of x + 2^31 */
int32_t acn_avr_add_sat32(int32_t b, int32_t a, uint32_t *overflow); /* acn_add_sat32(a, b, overflow) */
__asm__(".section .text.acn_avr,\"ax\",@progbits\n"
        ".weak acn_avr_smac\n.type acn_avr_smac, @function\n"
        ".weak acn_avr_umac\n.type acn_avr_umac, @function\n"
        ".weak acn_avr_rshr32\n.type acn_avr_rshr32, @function\n"
        ".weak acn_avr_hi_round\n.type acn_avr_hi_round, @function\n"
        ".weak acn_avr_add_sat32\n.type acn_avr_add_sat32, @function\n"
        /* signed: a b = ua ub - 2^32 ((a < 0) ub + (b < 0) ua) mod 2^64, the corrections first */
        "acn_avr_smac:\n"
        "sbrs r17, 7\nrjmp 1f\nsub r22, r10\nsbc r23, r11\nsbc r24, r12\nsbc r25, r13\n"
        "1: sbrs r13, 7\nrjmp 2f\nsub r22, r14\nsbc r23, r15\nsbc r24, r16\nsbc r25, r17\n2:\n"
        /* acc += ua ub by columns (the byte products of one weight, then the next): each product adds
         * into two bytes of acc, their carry into r26, which joins acc two bytes up before the next
         * column (r27 = 0) */
        "acn_avr_umac:\n"
        "clr r26\nclr r27\n"
        "mul r14, r10\nadd r18, r0\nadc r19, r1\nadc r26, r27\n"
        "add r20, r26\nclr r26\nadc r26, r27\nmul r14, r11\nadd r19, r0\nadc r20, r1\nadc r26, r27\nmul r15, r10\nadd r19, r0\nadc r20, r1\nadc r26, r27\n"
        "add r21, r26\nclr r26\nadc r26, r27\nmul r14, r12\nadd r20, r0\nadc r21, r1\nadc r26, r27\nmul r15, r11\nadd r20, r0\nadc r21, r1\nadc r26, r27\nmul r16, r10\nadd r20, r0\nadc r21, r1\nadc r26, r27\n"
        "add r22, r26\nclr r26\nadc r26, r27\nmul r14, r13\nadd r21, r0\nadc r22, r1\nadc r26, r27\nmul r15, r12\nadd r21, r0\nadc r22, r1\nadc r26, r27\nmul r16, r11\nadd r21, r0\nadc r22, r1\nadc r26, r27\nmul r17, r10\nadd r21, r0\nadc r22, r1\nadc r26, r27\n"
        "add r23, r26\nclr r26\nadc r26, r27\nmul r15, r13\nadd r22, r0\nadc r23, r1\nadc r26, r27\nmul r16, r12\nadd r22, r0\nadc r23, r1\nadc r26, r27\nmul r17, r11\nadd r22, r0\nadc r23, r1\nadc r26, r27\n"
        "add r24, r26\nclr r26\nadc r26, r27\nmul r16, r13\nadd r23, r0\nadc r24, r1\nadc r26, r27\nmul r17, r12\nadd r23, r0\nadc r24, r1\nadc r26, r27\n"
        "add r25, r26\nmul r17, r13\nadd r24, r0\nadc r25, r1\n"
        "clr r1\nret\n"
        /* floor(x / 2^(s-1)) on the six bytes the result needs: bytes q..q+5 of x (q = (s-1) / 8, beyond
         * byte 7 x's sign, r26) by one jump into a table of register moves, then the remaining (s-1) % 8
         * bits (r27); then + 1 and one more bit: the same integer as (x + 2^(s-1)) >> s, whose low word is
         * bits 1..32 of those five bytes */
        "acn_avr_rshr32:\n"
        "mov r27, r16\ndec r27\nmov r30, r27\nlsr r30\nlsr r30\nlsr r30\nandi r27, 7\n"
        "mov r26, r25\nlsl r26\nsbc r26, r26\n"
        "ldi r31, 0\nsubi r30, lo8(-(pm(10f)))\nsbci r31, hi8(-(pm(10f)))\nijmp\n"
        "10: rjmp 20f\nrjmp 21f\nrjmp 22f\nrjmp 23f\nrjmp 24f\nrjmp 25f\nrjmp 26f\nrjmp 27f\n"
        "20: rjmp 3f\n"
        "21: mov r18, r19\nmov r19, r20\nmov r20, r21\nmov r21, r22\nmov r22, r23\nmov r23, r24\nrjmp 3f\n"
        "22: movw r18, r20\nmovw r20, r22\nmovw r22, r24\nrjmp 3f\n"
        "23: mov r18, r21\nmov r19, r22\nmov r20, r23\nmov r21, r24\nmov r22, r25\nmov r23, r26\nrjmp 3f\n"
        "24: movw r18, r22\nmovw r20, r24\nmov r22, r26\nmov r23, r26\nrjmp 3f\n"
        "25: mov r18, r23\nmov r19, r24\nmov r20, r25\nmov r21, r26\nmov r22, r26\nmov r23, r26\nrjmp 3f\n"
        "26: movw r18, r24\nmov r20, r26\nmov r21, r26\nmov r22, r26\nmov r23, r26\nrjmp 3f\n"
        "27: mov r18, r25\nmov r19, r26\nmov r20, r26\nmov r21, r26\nmov r22, r26\nmov r23, r26\n"
        "3: tst r27\nbreq 5f\n"
        "4: asr r23\nror r22\nror r21\nror r20\nror r19\nror r18\ndec r27\nbrne 4b\n"
        "5: subi r18, 0xff\nsbci r19, 0xff\nsbci r20, 0xff\nsbci r21, 0xff\nsbci r22, 0xff\n"
        "asr r22\nror r21\nror r20\nror r19\nror r18\n"
        "movw r22, r18\nmovw r24, r20\nret\n"
        /* x - (-2^31): bytes 3..7 only (the lower three subtract 0) */
        "acn_avr_hi_round:\n"
        "subi r21, 0x80\nsbci r22, 0xff\nsbci r23, 0xff\nsbci r24, 0xff\nsbci r25, 0xff\nret\n"
        /* b (r22..r25) + a (r18..r21); on a signed overflow a's bound (INT32_MIN or INT32_MAX) and one more
         * in *overflow (r16:r17) */
        "acn_avr_add_sat32:\n"
        "add r22, r18\nadc r23, r19\nadc r24, r20\nadc r25, r21\nbrvs 1f\nret\n"
        "1: ldi r22, 0xff\nldi r23, 0xff\nldi r24, 0xff\nldi r25, 0x7f\nsbrs r21, 7\nrjmp 2f\n"
        "ldi r22, 0\nldi r23, 0\nldi r24, 0\nldi r25, 0x80\n"
        "2: movw r30, r16\nld r18, Z\nldd r19, Z+1\nldd r20, Z+2\nldd r21, Z+3\n"
        "subi r18, 0xff\nsbci r19, 0xff\nsbci r20, 0xff\nsbci r21, 0xff\n"
        "st Z, r18\nstd Z+1, r19\nstd Z+2, r20\nstd Z+3, r21\nret\n"
        ".text\n");
#endif

#if !defined(ACN_MATH)
#define ACN_MATH static inline
#endif

/* a b as int64: one SMULL. gcc for Cortex-M3 sometimes builds it from UMULL and two MLA (a 64x64
 * product), so on Thumb-2 it is spelled out; the result is the same integer everywhere. */
ACN_MATH int64_t acn_mul(int32_t a, int32_t b)
{
#if defined(ACN_AVR_ASM) /* b, the generator's constant if any, into r14..r17: two of its bytes take an LDI */
    return acn_avr_smac(0, b, a);
#elif defined(__arm__) && defined(__thumb2__)
    uint32_t lo, hi;
    __asm__("smull %0, %1, %2, %3" : "=&r"(lo), "=&r"(hi) : "r"(a), "r"(b));
    return (int64_t)(((uint64_t)hi << 32) | lo);
#else
    return (int64_t)a * b;
#endif
}

/* acc + a b as int64: one SMLAL (gcc for Cortex-M3 often forms the product with SMULL and adds it
 * with ADDS/ADC); the same integer everywhere. */
ACN_MATH int64_t acn_mac(int64_t acc, int32_t a, int32_t b)
{
#if defined(ACN_AVR_ASM)
    return acn_avr_smac(acc, b, a);
#elif defined(__arm__) && defined(__thumb2__)
    uint32_t lo = (uint32_t)acc, hi = (uint32_t)((uint64_t)acc >> 32);
    __asm__("smlal %0, %1, %2, %3" : "+r"(lo), "+r"(hi) : "r"(a), "r"(b));
    return (int64_t)(((uint64_t)hi << 32) | lo);
#else
    return acc + (int64_t)a * b;
#endif
}

/* a b as int64 where the compiler multiplies well by itself and may fold the product into what follows
 * (a shift, an add: gcc for Cortex-M3 does, through an asm it cannot); the AVR routine on AVR. */
ACN_MATH int64_t acn_wmul(int32_t a, int32_t b)
{
#if defined(ACN_AVR_ASM)
    return acn_avr_smac(0, b, a);
#else
    return (int64_t)a * b;
#endif
}

/* The high word of acc + a b (an SMLAL's high register). */
ACN_MATH int32_t acn_mac_hi(int64_t acc, int32_t a, int32_t b)
{
#if defined(ACN_AVR_ASM)
    return acn_avr_smac_hi(acc, b, a);
#else
    return (int32_t)(acn_mac(acc, a, b) >> 32);
#endif
}

/* a b, unsigned 32 x 32 -> 64. */
ACN_MATH uint64_t acn_umul(uint32_t a, uint32_t b)
{
#if defined(ACN_AVR_ASM)
    return acn_avr_umac(0, a, b);
#else
    return (uint64_t)a * b;
#endif
}

/* The high word of x + 2^31: x's high word rounded to nearest (ties up). */
ACN_MATH int32_t acn_hi_round(int64_t x)
{
#if defined(ACN_AVR_ASM)
    return acn_avr_hi_round(x);
#else
    return (int32_t)(((uint64_t)x + UINT64_C(0x80000000)) >> 32);
#endif
}

/* (x + 2^(s-1)) >> s for 1 <= s <= 63, as an int32: its low word when it does not fit (the same
 * integer as the cast of ACN_RSHR(x, s), which every target here wraps). */
ACN_MATH int32_t acn_rshr32(int64_t x, int s)
{
#if defined(ACN_AVR_ASM)
    return acn_avr_rshr32(x, (uint8_t)s);
#else
    return (int32_t)(uint32_t)(uint64_t)((x + ((int64_t)1 << (s - 1))) >> s);
#endif
}

/* (a b + 2^(s-1)) >> s, 1 <= s <= 63, as acn_rshr32. */
ACN_MATH int32_t acn_mul_rshr32(int32_t a, int32_t b, int s)
{
    return acn_rshr32(acn_mul(a, b), s);
}

/* acc + a b + c d as int64: two SMLAL in a row (the register pair is not copied between them). */
static inline int64_t acn_mac2(int64_t acc, int32_t a, int32_t b, int32_t c, int32_t d)
{
#if defined(__arm__) && defined(__thumb2__)
    uint32_t lo = (uint32_t)acc, hi = (uint32_t)((uint64_t)acc >> 32);
    __asm__("smlal %0, %1, %2, %3\n\tsmlal %0, %1, %4, %5" : "+r"(lo), "+r"(hi) : "r"(a), "r"(b), "r"(c), "r"(d));
    return (int64_t)(((uint64_t)hi << 32) | lo);
#else
    return acc + (int64_t)a * b + (int64_t)c * d;
#endif
}

/* w += c a on w's two words (lo, hi) in place, then p = (w >> s) + k y (p's words plo, phi; the shift
 * a floor, 1 <= s <= 31): two SMLAL and three shifts in one asm, w left in its registers for a later
 * SMLAL (apart, gcc copies w's and p's register pairs between them); the same integers everywhere. */
#if defined(__arm__) && defined(__thumb2__)
#define ACN_MAC_SHR_MAC(lo, hi, c, a, s, k, y, plo, phi)                                                 \
    __asm__("smlal %0, %1, %4, %5\n\tlsr %2, %0, #%c6\n\torr %2, %2, %1, lsl #%c7\n\tasr %3, %1, #%c6\n\t" \
            "smlal %2, %3, %8, %9"                                                                      \
            : "+r"(lo), "+r"(hi), "=&r"(plo), "=&r"(phi)                                               \
            : "r"(c), "r"(a), "i"(s), "i"(32 - (s)), "r"(k), "r"(y))
#else
#define ACN_MAC_SHR_MAC(lo, hi, c, a, s, k, y, plo, phi)                                                 \
    do {                                                                                                \
        int64_t w_ = (int64_t)(((uint64_t)(hi) << 32) | (lo)) + (int64_t)(c) * (a);                     \
        int64_t p_ = (w_ >> (s)) + (int64_t)(k) * (y);                                                  \
        (lo) = (uint32_t)w_;                                                                            \
        (hi) = (uint32_t)((uint64_t)w_ >> 32);                                                          \
        (plo) = (uint32_t)p_;                                                                           \
        (phi) = (uint32_t)((uint64_t)p_ >> 32);                                                         \
    } while (0)
#endif

/* a + ((t + 2^(s-1)) >> s) in 32 bits (wrapping as the int32 sum does), 1 <= s <= 32, from t's two
 * words: t >> s = hi 2^(32-s) + lo >> s, and the half added before the floor is the carry of
 * ((lo >> (s-1)) + 1) >> 1 (one shifted add each: no 64-bit add). */
static inline int32_t acn_add_round(int32_t a, int64_t t, int s)
{
    uint32_t lo = (uint32_t)t, hi = (uint32_t)((uint64_t)t >> 32);
    uint32_t h = s == 32 ? hi : hi << (32 - s);
    return (int32_t)((uint32_t)a + h + (((lo >> (s - 1)) + 1u) >> 1));
}

/* The bits of x in reverse order (one RBIT on Thumb-2): the bit-reversed sample count runs through
 * the rounding offsets of the covariance predict evenly (see codegen.emit_c._acc). */
static inline uint32_t acn_rbit(uint32_t x)
{
#if defined(__arm__) && defined(__thumb2__)
    __asm__("rbit %0, %1" : "=r"(x) : "r"(x));
    return x;
#else
    x = ((x >> 1) & UINT32_C(0x55555555)) | ((x & UINT32_C(0x55555555)) << 1);
    x = ((x >> 2) & UINT32_C(0x33333333)) | ((x & UINT32_C(0x33333333)) << 2);
    x = ((x >> 4) & UINT32_C(0x0F0F0F0F)) | ((x & UINT32_C(0x0F0F0F0F)) << 4);
    x = ((x >> 8) & UINT32_C(0x00FF00FF)) | ((x & UINT32_C(0x00FF00FF)) << 8);
    return (x >> 16) | (x << 16);
#endif
}

/* Narrow an int64 to int32, saturating and counting. x fits int32 exactly when its high word is the
 * sign extension of its low word: one compare on the common path. */
static inline int32_t acn_sat32(int64_t x, uint32_t *overflow)
{
    int32_t lo = (int32_t)(uint32_t)x, hi = (int32_t)(x >> 32);
    if (__builtin_expect(hi != (lo >> 31), 0)) {
        ++*overflow;
        return hi < 0 ? INT32_MIN : INT32_MAX;
    }
    return lo;
}

/* a + b saturated to int32, counting: the same value and count as acn_sat32((int64_t)a + b) (the
 * 32-bit add overflows exactly when the sum leaves int32, and then the sum has a's sign); one ADDS
 * and one branch on the overflow flag in the common case. */
ACN_MATH int32_t acn_add_sat32(int32_t a, int32_t b, uint32_t *overflow)
{
#if defined(ACN_AVR_ASM)
    return acn_avr_add_sat32(b, a, overflow);
#elif defined(__GNUC__)
    int32_t r;
    if (__builtin_expect(__builtin_add_overflow(a, b, &r), 0)) {
        ++*overflow;
        return a < 0 ? INT32_MIN : INT32_MAX;
    }
    return r;
#else
    return acn_sat32((int64_t)a + b, overflow);
#endif
}

/* Clamp an int64 to +-hmax 2^32 when its high word leaves [-hmax, hmax], counting: one add and
 * one compare on the high word in the common case. */
static inline int64_t acn_limit(int64_t x, int32_t hmax, uint32_t *overflow)
{
    if ((uint32_t)(x >> 32) + (uint32_t)hmax > 2u * (uint32_t)hmax) {
        ++*overflow;
        return x < 0 ? -(int64_t)hmax * ((int64_t)1 << 32) : (int64_t)hmax * ((int64_t)1 << 32);
    }
    return x;
}

/* round(x * c / 2^s) for int64 x, int32 c, 1 <= s <= 62, without a 96-bit
 * product: x = hi 2^32 + lo, lo unsigned. Contract: the result fits int64. */
#if defined(ACN_AVR_ASM) /* one copy for every axis' read: half a kilobyte each on AVR, and no step calls it */
static __attribute__((noinline, unused)) int64_t acn_mul64x32(int64_t x, int32_t c, int s)
#else
static inline int64_t acn_mul64x32(int64_t x, int32_t c, int s)
#endif
{
    int64_t hi = (x >> 32) * c;                          /* |.| < 2^62 */
    int64_t t = (int64_t)(uint32_t)(x & UINT32_C(0xFFFFFFFF)) * c; /* |.| < 2^63 */
    int64_t m = hi + (t >> 32);                          /* x c = m 2^32 + (t mod 2^32) */
    if (s > 32) {
        return (m + ((int64_t)1 << (s - 33))) >> (s - 32);
    }
    return m * ((int64_t)1 << (32 - s)) +
           (int64_t)((((uint64_t)(uint32_t)(t & UINT32_C(0xFFFFFFFF))) + ((uint64_t)1 << (s - 1))) >> s);
}

/* The leading zeros of a 32-bit d > 0. __builtin_clz counts them in an unsigned int, which is 16 bits
 * on AVR (it would count the zeros of d's low half): the builtin whose operand is exactly 32 bits is
 * chosen at compile time, and a plain binary search serves any other compiler or width (and
 * ACN_PLAIN_CLZ, which the tests use to check it). */
static inline int acn_clz32(uint32_t d)
{
#if defined(__GNUC__) && !defined(ACN_PLAIN_CLZ) && UINT_MAX == 0xFFFFFFFF
    return __builtin_clz(d);
#elif defined(__GNUC__) && !defined(ACN_PLAIN_CLZ) && ULONG_MAX == 0xFFFFFFFF
    return __builtin_clzl(d);
#else
    int n = 0;
    if (d < UINT32_C(0x10000)) {
        n += 16;
        d <<= 16;
    }
    if (d < UINT32_C(0x1000000)) {
        n += 8;
        d <<= 8;
    }
    if (d < UINT32_C(0x10000000)) {
        n += 4;
        d <<= 4;
    }
    if (d < UINT32_C(0x40000000)) {
        n += 2;
        d <<= 2;
    }
    return d < UINT32_C(0x80000000) ? n + 1 : n;
#endif
}

/* Reciprocal without a divide: for d > 0 returns x (Q2.30, 1 < x <= 2) and n = clz(d)
 * with 1/d = x 2^(n-62) to a relative 2^-28. Newton-Raphson, three steps from
 * the linear start 48/17 - 32/17 D, D = d 2^(n-32) in [0.5, 1). */
ACN_MATH uint32_t acn_umulhi(uint32_t a, uint32_t b)
{
#if defined(ACN_AVR_ASM)
    return (uint32_t)acn_avr_umac_hi(0, a, b);
#elif defined(__arm__) && defined(__thumb2__)
    uint32_t lo, hi;
    __asm__("umull %0, %1, %2, %3" : "=&r"(lo), "=&r"(hi) : "r"(a), "r"(b));
    (void)lo;
    return hi;
#else
    return (uint32_t)(((uint64_t)a * b) >> 32);
#endif
}

/* One Newton-Raphson step x += x (1 - D x) of the reciprocal below. On AVR the floor of the product by
 * 2^29 is the rounded shift of the product less half of 2^29 (one acn_avr_smac, one acn_avr_rshr32): the
 * same low word, no 64-bit shift or add from libgcc. */
#if defined(ACN_AVR_ASM)
#define ACN_NR(dn, x)                                                                                    \
    do {                                                                                                 \
        int32_t err_ = (int32_t)(UINT32_C(0x40000000) - acn_umulhi((dn), (x))); /* 1 - D x */             \
        (x) += (uint32_t)acn_rshr32(acn_mac(-(INT64_C(1) << 28), (int32_t)((x) >> 1), err_), 29);         \
    } while (0)
#else
#define ACN_NR(dn, x)                                                                        \
    do {                                                                                     \
        int32_t err_ = (int32_t)(UINT32_C(0x40000000) - acn_umulhi((dn), (x))); /* 1 - D x */ \
        (x) = (uint32_t)((int64_t)(x) + (acn_mul((int32_t)((x) >> 1), err_) >> 29));         \
    } while (0)
#endif

static inline uint32_t acn_recip(uint32_t d, int *n)
{
    uint32_t dn, x;
    *n = acn_clz32(d);
    dn = d << *n;                                                        /* D, Q0.32 */
    x = UINT32_C(3031741621) - acn_umulhi(UINT32_C(2021161080), dn); /* Q2.30 */
    ACN_NR(dn, x); /* three steps, unrolled */
    ACN_NR(dn, x);
    ACN_NR(dn, x);
    return x;
}

/* Checkpoint images (T_save, T_load): little-endian words at any alignment, no libc. A little-endian
 * target with unaligned access (Cortex-M3, x86) moves a word with one STR / LDR (a 4-byte
 * __builtin_memcpy); any other byte by byte (on the Cortex-M0 gcc would call memcpy). */
#if defined(__GNUC__) && defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__ &&                  \
    (defined(__ARM_FEATURE_UNALIGNED) || defined(__x86_64__) || defined(__i386__))
static inline void acn_put32(uint8_t *p, uint32_t v)
{
    __builtin_memcpy(p, &v, 4);
}

static inline uint32_t acn_get32(const uint8_t *p)
{
    uint32_t v;
    __builtin_memcpy(&v, p, 4);
    return v;
}
#else
static inline void acn_put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

static inline uint32_t acn_get32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
#endif
/* clang-format on */

#endif
