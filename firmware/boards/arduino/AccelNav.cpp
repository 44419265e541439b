/* AccelNav (AccelNav.h) and the board interface (acn_board.h) on the Arduino core: the firmware's
 * application (acn_app.c: filters, compact telemetry, commands) runs behind the class. */
#include <Arduino.h>
#include <math.h>
#include <string.h>

#include "AccelNav.h"
#include "acn_names.h"
#include "acn_model.h"

extern "C" {
#include "acn_app.h"
}

#define TX_NEED ACN_TX_NEED /* acn_board.h */
/* the most one received byte can make the application send, and 48 B of slack for the frames still
 * going out while a command is taken (a power of two would round a 3-axis model's 519 B up to 1
 * KiB; 48 rather than the AVR board's 64 keeps a 3-axis sketch within an Uno's RAM beside the
 * stack) */
#define TX_SIZE (TX_NEED + 48u)

static uint8_t acn_tx_ring[TX_SIZE]; /* indices wrap at TX_SIZE by a compare: any size */
static uint16_t acn_tx_head, acn_tx_tail, acn_tx_used;
static bool acn_binary; /* frames go out; otherwise they are not made (the app is stopped) */

static const uint8_t acn_pins[ACNF_NAXES] = ACN_PINS;
#define ACN_NAME(name, NAME, i) #name,
static const char *const acn_names[ACNF_NAXES] = {ACNF_AXES(ACN_NAME)};
/* fraction bits of r, u, a, e: each axis' output formats (accelnav.h) */
#define ACN_FRAC(name, NAME, i)                                                                    \
    {ACCELNAV_##NAME##_R_FRAC, ACCELNAV_##NAME##_U_FRAC, ACCELNAV_##NAME##_A_FRAC,                 \
     ACCELNAV_##NAME##_E_FRAC},
static const int8_t acn_frac[ACNF_NAXES][4] = {ACNF_AXES(ACN_FRAC)};

static uint16_t acn_tx_free(void)
{
    return (uint16_t)(TX_SIZE - acn_tx_used);
}

extern "C" bool acn_board_uart_write(const uint8_t *p, size_t n)
{
    size_t i;
    if (n > acn_tx_free()) {
        return false; /* the application counts it (tx_drop): the link is too slow for the rate */
    }
    for (i = 0; i < n; ++i) {
        acn_tx_ring[acn_tx_head] = p[i];
        if (++acn_tx_head == TX_SIZE) {
            acn_tx_head = 0u;
        }
    }
    acn_tx_used = (uint16_t)(acn_tx_used + n);
    return true;
}

extern "C" uint32_t acn_board_time_ms(void)
{
    return millis();
}

extern "C" uint8_t acn_board_id(void)
{
    return ACNF_BOARD_ARDUINO;
}

extern "C" uint16_t acn_board_boot_id(void)
{
    return 1u; /* no counter kept in EEPROM: the value the host board uses too */
}

extern "C" uint32_t acn_board_rx_lost(void)
{
    return 0u; /* the core's serial ring drops what overflows it without a count */
}

void AccelNav::begin()
{
    /* before any analogRead: an external reference on AREF while the ADC drives AVCC onto it
     * shorts the two (the Arduino reference's warning) */
    analogReference(ACN_AREF);
    acn_tx_head = acn_tx_tail = acn_tx_used = 0;
    acn_app_init();
    acn_binary = mode_ == BINARY && out_ != nullptr;
    acn_app.running = acn_binary; /* stopped: filters only, no frame made */
    refused_ = false;
    left_ = 0;
    ticks_ = 0;
    scheduled_ = false;
}

bool AccelNav::update(const uint16_t *codes)
{
    acnf_stimulus_t in;
    uint16_t skipped = acn_app.skipped;
    memset(&in, 0, sizeof in);
    for (uint8_t i = 0; i < ACNF_NAXES; ++i) {
        in.code[i] = codes[i];
    }
    acn_app_sample(&in);
    refused_ = acn_app.skipped != skipped;
    if (text_ != nullptr && ++left_ >= every_) {
        left_ = 0;
        (this->*text_)(*out_);
    }
    return !refused_;
}

bool AccelNav::update()
{
    uint16_t code[ACNF_NAXES];
    for (uint8_t i = 0; i < ACNF_NAXES; ++i) {
        code[i] = (uint16_t)analogRead(acn_pins[i]);
    }
    return update(code);
}

void AccelNav::missed(uint16_t n)
{
    acn_app_missed(n);
}

bool AccelNav::due()
{
    /* the period is 1e9 / ACNF_RATE_MHZ us: whole microseconds, the remainder carried */
    const uint32_t q = 1000000000UL / ACNF_RATE_MHZ, r = 1000000000UL % ACNF_RATE_MHZ;
    uint32_t now = micros();
    uint16_t n = 0;
    if (!scheduled_) {
        scheduled_ = true;
        next_us_ = now;
        rem_ = 0;
    }
    while ((int32_t)(now - next_us_) >= 0 && n < 0xffffu) {
        next_us_ += q;
        rem_ += r;
        if (rem_ >= ACNF_RATE_MHZ) {
            rem_ -= ACNF_RATE_MHZ;
            ++next_us_;
        }
        ++n;
    }
    if (n > 1u) {
        missed((uint16_t)(n - 1u));
    }
    return n > 0u;
}

void AccelNav::tick()
{
    if (ticks_ < 0xffffu) {
        ++ticks_;
    }
}

void AccelNav::service()
{
    if (!acn_binary) {
        return;
    }
    while (acn_tx_free() >= TX_NEED && out_->available() > 0) {
        uint8_t b = (uint8_t)out_->read();
        acn_app_rx(APP_CH_HOST, &b, 1);
    }
    while (acn_tx_used > 0u && out_->availableForWrite() > 0) {
        out_->write(acn_tx_ring[acn_tx_tail]);
        if (++acn_tx_tail == TX_SIZE) {
            acn_tx_tail = 0u;
        }
        --acn_tx_used;
    }
}

bool AccelNav::poll()
{
    uint16_t n;
    noInterrupts();
    n = ticks_;
    ticks_ = 0;
    interrupts();
    if (n > 1u) {
        missed((uint16_t)(n - 1u)); /* their input is gone: predict over them */
    }
    if (n > 0u) {
        update();
    }
    service();
    return n > 0u;
}

/* Timer1's clock ticks per sample period at prescaler d: the smallest d whose count fits 16 bits,
 * the finest period. The period is whole ticks: a rate that does not divide F_CPU runs off by at
 * most one tick in ACN_T1_TOP + 1 (1 in 8192 below 1.9 kHz), which the filter's Ts does not know.
 */
#define ACN_T1_TICKS(d) ((F_CPU * 1000ULL / (d)) / ACNF_RATE_MHZ)
#if ACN_T1_TICKS(1) <= 65536ULL
#define ACN_T1_CS 1u
#define ACN_T1_TOP (ACN_T1_TICKS(1) - 1u)
#elif ACN_T1_TICKS(8) <= 65536ULL
#define ACN_T1_CS 2u
#define ACN_T1_TOP (ACN_T1_TICKS(8) - 1u)
#elif ACN_T1_TICKS(64) <= 65536ULL
#define ACN_T1_CS 3u
#define ACN_T1_TOP (ACN_T1_TICKS(64) - 1u)
#elif ACN_T1_TICKS(256) <= 65536ULL
#define ACN_T1_CS 4u
#define ACN_T1_TOP (ACN_T1_TICKS(256) - 1u)
#elif ACN_T1_TICKS(1024) <= 65536ULL
#define ACN_T1_CS 5u
#define ACN_T1_TOP (ACN_T1_TICKS(1024) - 1u)
#else
#define ACN_T1_CS 0u /* slower than F_CPU / 1024 / 65536: out of reach */
#define ACN_T1_TOP 0u
#endif

bool AccelNav::startTimer1()
{
    if (ACN_T1_CS == 0u || ACN_T1_TOP < 1u) {
        return false;
    }
    noInterrupts();
    TCCR1A = 0;
    TCCR1B = (uint8_t)(_BV(WGM12) | ACN_T1_CS); /* CTC on OCR1A; CS12..10: the prescaler */
    OCR1A = (uint16_t)ACN_T1_TOP;
    TCNT1 = 0;
    TIMSK1 = _BV(OCIE1A);
    interrupts();
    return true;
}

static acnf_axis_t acn_read(uint8_t axis)
{
    acnf_axis_t ax;
    memset(&ax, 0, sizeof ax);
    if (axis < ACNF_NAXES) {
        acn_filter_read(&acn_app.filters, axis, &ax);
    }
    return ax;
}

static float acn_real(int64_t v, int8_t frac)
{
    return ldexp((float)v, -frac);
}

float AccelNav::position(uint8_t axis) const
{
    return axis < ACNF_NAXES ? acn_real(acn_read(axis).r, acn_frac[axis][0]) : NAN;
}

float AccelNav::velocity(uint8_t axis) const
{
    return axis < ACNF_NAXES ? acn_real(acn_read(axis).u, acn_frac[axis][1]) : NAN;
}

float AccelNav::acceleration(uint8_t axis) const
{
    return axis < ACNF_NAXES ? acn_real(acn_read(axis).a, acn_frac[axis][2]) : NAN;
}

float AccelNav::bias(uint8_t axis) const
{
    return axis < ACNF_NAXES ? acn_real(acn_read(axis).e, acn_frac[axis][3]) : NAN;
}

uint8_t AccelNav::status() const
{
    uint8_t s = refused_ ? REFUSED : 0u;
    if (acn_app_overflow_total() > 0u) {
        s |= SATURATED;
    }
    if (acn_app.missed > 0u) {
        s |= MISSED;
    }
    if (acn_app.tx_drop > 0u) {
        s |= DROPPED;
    }
    return s;
}

uint32_t AccelNav::samples() const
{
    return acn_app.index;
}

/* v * 2^-frac in decimal, six places, rounded half up on the magnitude by integer arithmetic (the
 * host reproduces the digits exactly); a fraction finer than 2^-43 is cut to 43 bits first, and a
 * whole part past 2^32 - 1 prints as 4294967295. */
static void acn_print_fixed(Print &out, int64_t v, int8_t frac)
{
    uint64_t m = v < 0 ? (uint64_t)0 - (uint64_t)v : (uint64_t)v;
    uint64_t whole = m, part = 0;
    uint32_t micro = 0;
    if (frac > 0) {
        whole = m >> frac;
        part = m - (whole << frac);
        if (frac > 43) {
            part >>= frac - 43;
            frac = 43;
        }
        micro = (uint32_t)((part * 1000000u + ((uint64_t)1 << (frac - 1))) >> frac);
        if (micro >= 1000000u) {
            ++whole;
            micro -= 1000000u;
        }
    }
    if (whole > 0xffffffffu) {
        whole = 0xffffffffu;
    }
    if (v < 0 && (whole > 0u || micro > 0u)) {
        out.print('-');
    }
    out.print((unsigned long)whole);
    out.print('.');
    for (uint32_t d = 100000u; d > 0u; d /= 10u) {
        out.print((char)('0' + micro / d % 10u));
    }
}

void AccelNav::printPositions(Print &out) const
{
    for (uint8_t i = 0; i < ACNF_NAXES; ++i) {
        if (i > 0u) {
            out.print(' ');
        }
        out.print(acn_names[i]);
        out.print(':');
        acn_print_fixed(out, acn_read(i).r, acn_frac[i][0]);
    }
    out.println();
}
