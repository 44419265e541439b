/* AccelnavStream: the accelnav filter of model '@MODEL@' on an Arduino Uno, streaming its
 * telemetry.
 *
 * Axes @PINS_DOC@, sampled at the model's rate (@RATE@ Hz) on Timer1, which this sketch chooses
 * (Servo and PWM on pins 9 and 10 need Timer1 too: take another timer and call nav.tick() from it).
 * The firmware's binary telemetry goes out on Serial at 115200 baud. Record it with
 *     accelnav record /dev/ttyACM0 --baud 115200 --manifest acnframe.json --out run.acnlog
 * (acnframe.json: in this library's extras/ folder). A tick that comes while loop() is still busy
 * is not lost: the filters predict over it. */
#include <AccelNav.h>

AccelNav nav;

ISR(TIMER1_COMPA_vect)
{
    nav.tick();
}

void setup()
{
    Serial.begin(115200);
    nav.begin(Serial, AccelNav::BINARY);
    nav.startTimer1();
}

void loop()
{
    nav.poll(); /* the ticks' samples (analogRead of every axis), frames out, commands in */
}
