/* @NAME@: the accelnav filter of model '@MODEL@' on an Arduino Uno.
 *
 * Axes @PINS_DOC@. Timer1 ticks at the model's rate (@RATE@ Hz); loop()
 * reads every axis with analogRead at each tick, runs the filter (acn_arduino_sample) and streams
 * the firmware's telemetry on Serial at 115200 baud: record it with
 *     accelnav record /dev/ttyACM0 --baud 115200 --manifest acnframe.json --out run.acnlog
 * (acnframe.json: beside this library, from `accelnav codegen MODEL --arduino DIR`).
 * A tick that comes while loop() is still busy is not lost: the filters predict over it. */
#include <acn_arduino.h>

/* Timer1 in CTC mode at clk/64: its period in ticks for the model's rate (ACNF_RATE_MHZ, in mHz) */
#define TIMER1_TOP ((F_CPU / 64UL * 1000UL) / ACNF_RATE_MHZ - 1UL)
#if TIMER1_TOP > 65535UL || TIMER1_TOP < 1UL
#error "the model's rate is out of Timer1's range at clk/64"
#endif

static const uint8_t pins[ACNF_NAXES] = {@PINS@};
static volatile uint16_t ticks; /* sample ticks not yet taken by loop() */

ISR(TIMER1_COMPA_vect)
{
    ++ticks;
}

void setup()
{
    Serial.begin(115200);
    acn_arduino_begin();
    noInterrupts();
    TCCR1A = 0;
    TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10); /* CTC on OCR1A, clk/64 */
    OCR1A = (uint16_t)TIMER1_TOP;
    TCNT1 = 0;
    TIMSK1 = _BV(OCIE1A);
    interrupts();
}

void loop()
{
    uint16_t n;
    noInterrupts();
    n = ticks;
    ticks = 0;
    interrupts();
    if (n > 1u) {
        acn_arduino_missed(n - 1u); /* their input is gone: predict over them */
    }
    if (n > 0u) {
        uint16_t code[ACNF_NAXES];
        for (uint8_t i = 0; i < ACNF_NAXES; ++i) {
            code[i] = (uint16_t)analogRead(pins[i]);
        }
        acn_arduino_sample(code);
    }
    acn_arduino_poll(Serial);
}
