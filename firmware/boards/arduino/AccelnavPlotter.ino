/* AccelnavPlotter: the accelnav filter of model '@MODEL@' on an Arduino Uno, its positions on the
 * Serial Plotter (Tools > Serial Plotter, 115200 baud).
 *
 * Axes @PINS_DOC@. The sketch keeps the schedule: nav.due() is true once per sample period of the
 * model's rate (@RATE@ Hz) by micros(); no timer is taken. Each sample prints one line, e.g.
 *     x:0.001234 y:-0.000020
 * (metres). nav.position(axis), nav.velocity(axis) and nav.bias(axis) give the same states as
 * numbers. */
#include <AccelNav.h>

AccelNav nav;

void setup()
{
    Serial.begin(115200);
    nav.begin();
}

void loop()
{
    if (nav.due()) {
        nav.update();               /* analogRead of every axis, one filter step */
        nav.printPositions(Serial); /* or: Serial.println(nav.position(0), 6); */
    }
}
