/* The board interface: what the application needs from a board, and what a
 * board calls in the application.
 *
 * A board owns the main loop (board_run), its time base, the sample source
 * (ADC + DMA, timer capture, or a stimulus stream standing in for them) and
 * the UARTs. Telemetry goes out through board_uart_write(); received bytes and
 * samples go in through app_rx() and app_sample(). */
#ifndef ACN_BOARD_H
#define ACN_BOARD_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "acnframe.h"

/* Bytes of one frame on the wire: CRC 4, COBS code 1, delimiter 1 (every frame is < 254 bytes). */
#define ACN_WIRE(size) ((size) + 6u)
#define ACN_MAX2(a, b) ((a) > (b) ? (a) : (b))
/* The most telemetry one received byte or one sample can queue: it completes at most one frame,
 * and a sample (a block and every axis' checkpoint) or a command (flush: the same, then its ack;
 * info: info and ack) sends at most this much. A board with a telemetry ring takes a byte in only
 * while the ring has this much room, so that a command never costs a frame. */
#define ACN_TX_NEED                                                                                \
    (ACN_MAX2(ACN_MAX2(ACN_WIRE(ACNF_BLOCK_SIZE) + ACNF_NAXES * ACN_WIRE(ACNF_CHECKPOINT_SIZE),    \
                       ACN_WIRE(ACNF_SAMPLE_SIZE)),                                                \
              ACN_WIRE(ACNF_INFO_SIZE)) +                                                          \
     ACN_WIRE(ACNF_ACK_SIZE))

/* Set up clocks, pins, UARTs and the sample source. */
void board_init(void);

/* One pass of the main loop: feed received bytes and ready samples to the
 * application, move queued telemetry out. Returns false when the board has
 * nothing more to do (host board at end of input); MCU boards never return false. */
bool board_poll(void);

/* Queue n telemetry bytes for the host link; all or nothing (false: no room, nothing queued). */
bool board_uart_write(const uint8_t *p, size_t n);

/* Milliseconds since board_init, wrapping. */
uint32_t board_time_ms(void);

/* ACNF_BOARD_* of this board. */
uint8_t board_id(void);

/* An id that differs from one power-on to the next (a counter kept over resets, a hardware
 * random number); the compact frames carry it so that the host tells a reboot from re-sent
 * power-on frames. Boards without either return a fixed value, the same on the host board and
 * every emulated one, so that SIL and PIL telemetry stay bit-identical. */
uint16_t board_boot_id(void);

/* Bytes the board's receivers lost since board_init (hardware overrun, full ring), wrapping. */
uint32_t board_rx_lost(void);

/* ---- implemented by the application (firmware/src/app.c) ---- */

/* Channels of app_rx(): they carry the same frames; each has its own receiver. */
/* A board with no stimulus link (the Arduino library reads its own ADC) defines
 * ACN_NO_STIM_CHANNEL: the application keeps one receive buffer less, and bytes given for the
 * stimulus channel are refused. */
#if defined(ACN_NO_STIM_CHANNEL)
#define APP_HAS_STIM 0
enum { APP_CH_HOST = 0, APP_CH_STIM = 1, APP_NCH = 1 };
#else
#define APP_HAS_STIM 1
enum { APP_CH_HOST = 0, APP_CH_STIM = 1, APP_NCH = 2 };
#endif

void app_init(void);
/* The raw input of one sample: ADC codes or T1/T2 counts, and per axis a
 * no-capture flag (bit i: axis i saw no duty-cycle period: sensor unplugged). */
void app_sample(const acnf_stimulus_t *in);
/* n sample periods passed whose input the board missed (its main loop was too slow to take them):
 * every axis filter predicts over each (the filter's skip), the sample index advances, the sample
 * frame's `missed` counter counts them; no frame is sent for them. */
void app_missed(uint32_t n);
/* Bytes received on a channel: commands, and stimulus frames (which call app_sample). */
void app_rx(unsigned ch, const uint8_t *p, size_t n);

#endif
