/* The file feed of the atmega328p board in simavr: the host half, a small program built with the
 * host's cc against libsimavr (Debian: libsimavr-dev) by accelnav.hil_sim.targets.simavr.
 *
 *     simavr_feed FIRMWARE.elf STIMULUS.bin TELEMETRY.bin MAX_CYCLES
 *
 * simavr's own command-line tool prints the UART's output but cannot feed its input. This program
 * loads the image on a 16 MHz ATmega328P, feeds STIMULUS.bin into USART0 (the bytes the host board
 * reads on stdin: stimulus and command frames), once the board is up (PB5's first rise), as fast as
 * the UART's FIFO takes them (simavr's XON and XOFF), and writes every byte the firmware sends on
 * USART0 to TELEMETRY.bin. The firmware raises PB5 while it is idle (board_atmega328p.c): once the
 * last byte has been fed and PB5 has risen again and stayed high for several byte times, the run
 * ends, after the time of a few more bytes on the line so that the last one is out.
 *
 *     simavr_feed SKETCH.elf COMMANDS.bin TELEMETRY.bin MAX_CYCLES CODES.bin AXES
 *
 * The second form runs an Arduino sketch that reads its input with analogRead (accelnav codegen
 * --arduino): CODES.bin holds AXES little-endian uint16 ADC codes per sample, and each conversion
 * the sketch starts on channel i (simavr's ADC trigger) gets the next code of axis i: AVCC is set
 * to 1023 "mV", so that simavr's conversion (mV * 1023 / AVCC) gives the code itself. Once every
 * code has been converted, COMMANDS.bin is fed into USART0 (e.g. a stop, which flushes the last
 * block); the run ends when nothing has come out of the UART for 20 ms of simulated time. With an
 * empty COMMANDS.bin (a sketch that streams text and takes no command) it ends 20 ms after the
 * first conversion past the last code: every sample's output is out by then.
 *
 * On stdout: "cycles N stack S" (the CPU cycles of the run; the deepest stack seen, in bytes below
 * RAMEND) and, in the second form, "aref R": REFS1..0 of ADMUX at the first conversion (0: AREF,
 * external; 1: AVCC, the Arduino default; 3: the internal 1.1 V; -1: no conversion). Exit status 0;
 * 1 with a one-line reason on stderr if the image cannot be loaded, the core crashes or sleeps for
 * good, or MAX_CYCLES pass before the end. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/avr_adc.h>
#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_irq.h>

#define MCU "atmega328p"
#define F_CPU 16000000u
#define BYTE_CYCLES 640u /* one byte on the line at the board's 250000 baud, 10 bits */
/* The end: PB5 high for this long after the last byte was fed. simavr hands the FIFO's bytes to the
 * receiver one byte time apart, and the board is idle between them: a quiet stretch of several byte
 * times means the FIFO is empty. Then the time of a few more bytes, for the last one to go out. */
#define QUIET_CYCLES (8u * BYTE_CYCLES)
#define TAIL_CYCLES (8u * BYTE_CYCLES)

static FILE *out;
static int xon = 1;         /* the UART's FIFO takes another byte */
static unsigned idle_rises; /* PB5 rising edges */
static int idle;
static avr_t *avr;
static unsigned long long idle_since; /* the cycle of PB5's last rise */
static unsigned long long last_out;   /* the cycle of the last byte sent */
static uint8_t *codes; /* the ADC mode's codes: samples x axes, little-endian uint16 */
static unsigned long n_codes, axes, next_code[8];
static int adc_done;
static int refs = -1;                  /* ADMUX's REFS bits at the first conversion */
static unsigned long long past_end_at; /* the cycle of the first conversion past the last code */
static avr_irq_t *adc_in;

static void on_output(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    last_out = avr->cycle;
    if (fputc((int)(value & 0xffu), out) == EOF) {
        fprintf(stderr, "simavr_feed: cannot write the telemetry file\n");
        exit(1);
    }
}

static void on_xon(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    (void)param;
    xon = 1;
}

static void on_xoff(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)value;
    (void)param;
    xon = 0;
}

static void on_pb5(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    if (value && !idle) {
        ++idle_rises;
        idle_since = avr->cycle;
    }
    idle = value != 0;
}

/* a conversion starts: give its channel the next code of that axis (the last one, past the end) */
static void on_adc_start(struct avr_irq_t *irq, uint32_t value, void *param)
{
    union {
        avr_adc_mux_t mux;
        uint32_t v;
    } e;
    unsigned long ch, k, at, done = 0;
    (void)irq;
    (void)param;
    e.v = value;
    ch = e.mux.src;
    if (e.mux.kind != ADC_MUX_SINGLE || ch >= axes) {
        return;
    }
    if (refs < 0) {
        refs = avr->data[0x7c] >> 6; /* ADMUX (data address 0x7C): REFS1..0 in bits 7..6 */
    }
    if (next_code[ch] >= n_codes && !past_end_at) {
        past_end_at = avr->cycle;
    }
    k = next_code[ch] < n_codes ? next_code[ch]++ : n_codes - 1u;
    at = 2u * (k * axes + ch);
    avr_raise_irq(adc_in + ch, (uint32_t)(codes[at] | codes[at + 1u] << 8));
    for (ch = 0; ch < axes; ++ch) {
        done += next_code[ch] == n_codes;
    }
    adc_done = done == axes;
}

static void fail(const char *why)
{
    fprintf(stderr, "simavr_feed: %s\n", why);
    exit(1);
}

int main(int argc, char **argv)
{
    elf_firmware_t fw;
    FILE *in;
    uint32_t flags = 0;
    unsigned long long max_cycles, end_at = 0, fed_at = 0;
    unsigned rises_at_last = 0;
    int c, fed_all = 0, fed_any = 0;
    uint16_t sp, sp_min = 0xffffu;
    avr_irq_t *uart_in;
    if (argc != 5 && argc != 7) {
        fail("usage: simavr_feed FIRMWARE.elf STIMULUS.bin TELEMETRY.bin MAX_CYCLES [CODES.bin "
             "AXES]");
    }
    max_cycles = strtoull(argv[4], 0, 10);
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(argv[1], &fw) != 0) {
        fail("cannot read the firmware image");
    }
    avr = avr_make_mcu_by_name(MCU);
    if (!avr) {
        fail("libsimavr has no " MCU);
    }
    avr_init(avr);
    avr->frequency = F_CPU;
    avr->log = 0;
    avr_load_firmware(avr, &fw);
    in = fopen(argv[2], "rb");
    out = fopen(argv[3], "wb");
    if (!in || !out) {
        fail("cannot open the stimulus or the telemetry file");
    }
    /* no console printing, no host sleep while the firmware polls an empty receiver */
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            on_output, 0);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                            on_xon, 0);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                            on_xoff, 0);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), IOPORT_IRQ_PIN5),
                            on_pb5, 0);
    if (argc == 7) {
        FILE *f = fopen(argv[5], "rb");
        long size = -1;
        axes = strtoul(argv[6], 0, 10);
        if (!f || fseek(f, 0, SEEK_END) != 0 || (size = ftell(f)) <= 0 ||
            fseek(f, 0, SEEK_SET) != 0) {
            fail("cannot read the ADC codes");
        }
        if (axes < 1u || axes > 8u || (unsigned long)size % (2u * axes) != 0u) {
            fail("the ADC codes are not AXES uint16 per sample");
        }
        codes = malloc((size_t)size);
        if (!codes || fread(codes, 1, (size_t)size, f) != (size_t)size) {
            fail("cannot read the ADC codes");
        }
        fclose(f);
        n_codes = (unsigned long)size / (2u * axes);
        avr->avcc = avr->aref = avr->vcc = 1023; /* "mV" = code */
        adc_in = avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0);
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_OUT_TRIGGER),
                                on_adc_start, 0);
    }
    for (;;) {
        int state;
        /* the board: from PB5's first rise (its UART is set up); the sketch: once its codes are
         * taken */
        if (!fed_all && xon && (codes ? adc_done : idle_rises > 0)) {
            c = fgetc(in);
            if (c == EOF) {
                fed_all = 1;
                fed_at = avr->cycle;
                rises_at_last = idle_rises;
            } else {
                fed_any = 1;
                avr_raise_irq(uart_in, (uint32_t)c);
            }
        }
        state = avr_run(avr);
        if (state == cpu_Done || state == cpu_Crashed) {
            fail("the core stopped (crashed, or asleep with interrupts off)");
        }
        sp = (uint16_t)(avr->data[R_SPL] | avr->data[R_SPH] << 8);
        if (sp < sp_min) {
            sp_min = sp;
        }
        if (codes && fed_all && !fed_any && !end_at && past_end_at) {
            end_at = past_end_at + F_CPU / 50u;
        }
        if (codes && fed_all && !end_at && avr->cycle - last_out >= F_CPU / 50u &&
            avr->cycle - fed_at >= F_CPU / 50u) {
            end_at = avr->cycle;
        }
        if (!codes && fed_all && !end_at && idle && idle_rises > rises_at_last &&
            avr->cycle - idle_since >= QUIET_CYCLES) {
            end_at = avr->cycle + TAIL_CYCLES;
        }
        if (end_at && avr->cycle >= end_at) {
            break;
        }
        if (avr->cycle > max_cycles) {
            fail("the run did not end within its cycle limit");
        }
    }
    if (fclose(out) != 0) {
        fail("cannot write the telemetry file");
    }
    printf("cycles %llu stack %u\n", (unsigned long long)avr->cycle,
           (unsigned)(avr->ramend - sp_min));
    if (codes) {
        printf("aref %d\n", refs);
    }
    return 0;
}
