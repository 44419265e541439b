/* AccelNav: the accelnav filter of this library's model in an Arduino sketch (AVR core).
 *
 *     #include <AccelNav.h>
 *     AccelNav nav;
 *     setup(): nav.begin();                 the filters from their initial state; the ADC reference
 *                                           set from the model (before any analogRead)
 *     loop():  if (nav.due()) nav.update(); a sample on your schedule (analogRead of every axis),
 *              or nav.update(codes) with the 10-bit codes you read yourself
 *              nav.position(axis) [m], nav.velocity(axis) [m/s], nav.bias(axis) [m/s^2]
 *
 * Or on a timer you choose: call nav.tick() from its interrupt once per sample period and
 * nav.poll() from loop(); nav.startTimer1() sets Timer1 up for it (which takes Timer1 from Servo
 * and from PWM on pins 9 and 10: the library touches no timer unless you call it).
 *
 * Telemetry is optional: nav.begin(Serial, AccelNav::BINARY) streams the firmware's frames (COBS,
 * read by `accelnav record`, commands taken), nav.begin(Serial, AccelNav::TEXT) prints a line of
 * positions per sample ("x:0.001234 y:-0.000020", metres) for the Serial Monitor and Plotter.
 * Binary telemetry needs nav.poll() in every loop() pass (it moves the frames out, commands in).
 *
 * Every global name of the library starts with acn, accelnav or AccelNav. */
#ifndef ACN_ACCELNAV_H
#define ACN_ACCELNAV_H

#include <Arduino.h>
#include <stdint.h>

#include "acnframe.h"

#if ACNF_INPUT_DUTY
#error                                                                                             \
    "AccelNav: analogRead input only; a duty-cycle model needs timer capture (not in this library)"
#endif

class AccelNav
{
  public:
    enum Telemetry : uint8_t { NONE, BINARY, TEXT };
    /* bits of status() */
    enum : uint8_t {
        REFUSED = 1u,   /* the last sample's input was refused on some axis (a rail): predicted */
        SATURATED = 2u, /* a filter saturated since begin() (clamped states: distrust them) */
        MISSED = 4u,    /* sample periods passed unread since begin() (loop() too slow) */
        DROPPED = 8u,   /* telemetry that did not fit the link was dropped (binary mode) */
    };
    static const uint8_t AXES = ACNF_NAXES;

    /* The filters from their initial state; the telemetry as last chosen (none at first). */
    void begin();
    /* The same, with telemetry on out: BINARY frames, or a TEXT line every `every` samples. Inline,
     * so that a sketch that asks for no text links no text code. */
    void begin(Stream &out, Telemetry mode, uint16_t every = 1u)
    {
        out_ = &out;
        mode_ = mode;
        every_ = every > 0u ? every : 1u;
        text_ = mode == TEXT ? &AccelNav::printPositions : nullptr;
        begin();
    }

    /* One sample now: analogRead of every axis (pins A0, A1, ... in axis order). */
    bool update();
    /* One sample from codes[AXES] (10-bit ADC codes). True when every axis took its input. */
    bool update(const uint16_t *codes);
    /* n sample periods passed whose input was not read: every filter predicts over them. */
    void missed(uint16_t n);

    /* Your schedule by micros(): true once per sample period of the model's rate; periods that
     * passed while loop() was busy are predicted over (missed) before it returns true. */
    bool due();
    /* From your timer's interrupt, once per sample period. */
    void tick();
    /* From loop(): the periods tick() counted (the last one sampled, the others predicted over),
     * telemetry out, commands in. True when it took a sample. */
    bool poll();
    /* Timer1 in CTC mode at the model's rate (the finest prescaler that reaches it); your sketch
     * defines its interrupt:  ISR(TIMER1_COMPA_vect) { nav.tick(); }
     * False (and Timer1 untouched) when the rate is beyond Timer1's reach. */
    bool startTimer1();

    float position(uint8_t axis) const;     /* [m] */
    float velocity(uint8_t axis) const;     /* [m/s] */
    float acceleration(uint8_t axis) const; /* [m/s^2], the bias removed */
    float bias(uint8_t axis) const;         /* [m/s^2] */
    uint8_t status() const;                 /* REFUSED | SATURATED | MISSED | DROPPED */
    uint32_t samples() const;               /* sample periods since begin(), missed included */

    /* One text line: every axis' position in metres, six decimals ("x:0.001234 y:-0.000020"). */
    void printPositions(Print &out) const;

  private:
    void service();
    Stream *out_ = nullptr;
    Telemetry mode_ = NONE;
    void (AccelNav::*text_)(Print &out) const = nullptr;
    uint16_t every_ = 1u, left_ = 0u;
    bool refused_ = false;
    volatile uint16_t ticks_ = 0u;
    uint32_t next_us_ = 0u, rem_ = 0u;
    bool scheduled_ = false;
};

#endif
