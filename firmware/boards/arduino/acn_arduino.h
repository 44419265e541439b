/* accelnav on an Arduino (AVR core): the firmware's application (app.c: filters, compact telemetry,
 * commands) with the Arduino core as its board. The sketch owns the sample clock and the ADC:
 *
 *     setup(): Serial.begin(115200); acn_arduino_begin(); start a timer at ACNF_RATE_MHZ / 1000 Hz
 *     loop():  a tick missed while busy -> acn_arduino_missed(n); a tick -> analogRead every axis,
 *              acn_arduino_sample(codes); always acn_arduino_poll(Serial)
 *
 * Telemetry and commands are the firmware's protocol (firmware/README.md): `accelnav record` reads
 * the stream as it reads any board's. */
#ifndef ACN_ARDUINO_H
#define ACN_ARDUINO_H

#include <stdint.h>

#include "acnframe.h"

#if ACNF_INPUT_DUTY
#error                                                                                             \
    "acn_arduino: analogRead input only; a duty-cycle model needs timer capture (not in this library)"
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* The filters from their initial state, streaming from now (compact frames). */
void acn_arduino_begin(void);
/* One sample: the ADC code of every axis (ACNF_NAXES of them, 10 bits from analogRead). */
void acn_arduino_sample(const uint16_t *code);
/* n sample ticks passed whose input was not read (loop() was busy): every filter predicts over
 * them. */
void acn_arduino_missed(uint16_t n);

#ifdef __cplusplus
}

#include <Stream.h>
/* Received bytes from link into the application (commands), queued telemetry out to link: never
 * blocks (only what link can take now). A byte is read only while the telemetry ring has room for
 * all it can make the application send, so a command never costs a frame. */
void acn_arduino_poll(Stream &link);
#endif

#endif
