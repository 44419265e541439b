#include "app.h"

#include <string.h>

app_state_t app;

/* A frame's buffers (payload, then the framed copy) should be on the stack only while that frame is
 * sent. Inlined into their callers, the senders' buffers add up along a call path: 900 B of stack
 * on an ATmega328P, whose 2 KiB of RAM also hold the state and the telemetry ring. */
#if defined(__GNUC__)
#define APP_OUT_OF_LINE __attribute__((noinline))
#else
#define APP_OUT_OF_LINE
#endif

static bool app_compact(void)
{
    return ACNF_COMPACT && app.running && app.decimation == 1u && !app.state_mode;
}

/* One checkpoint per axis: the state before sample app.index. */
APP_OUT_OF_LINE static void app_send_checkpoints(uint8_t flags)
{
    acnf_checkpoint_t ck;
    uint8_t payload[ACNF_CHECKPOINT_SIZE];
    unsigned i;
    for (i = 0; i < ACNF_NAXES; ++i) {
        memset(&ck, 0, sizeof ck);
        ck.index = app.index;
        ck.flags = flags;
        ck.axis = (uint8_t)i;
        ck.run = app.run;
        ck.paused_at = app.paused_at;
        ck.seq = app.seq;
        acn_filter_state(&app.filters, i, ck.state);
        if (!link_send(payload, acnf_pack_checkpoint(&ck, payload))) {
            ++app.tx_drop; /* the host replays on to the next checkpoint: nothing is lost but a
                              check */
        }
    }
    app.ck_left = ACNF_CHECKPOINT_SAMPLES;
}

/* Send the block being filled (if it holds a sample) and begin the next at sample app.index. */
APP_OUT_OF_LINE static void app_send_block(void)
{
    acnf_block_t *b = &app.blk;
    uint32_t overflow = app_overflow_total();
    if (b->n > 0u) {
        uint8_t payload[ACNF_BLOCK_SIZE];
        b->flags |= ACNF_FLAG_RUNNING;
        if (app.zupt) {
            b->flags |= ACNF_FLAG_ZUPT;
        }
        if (overflow != app.overflow_seen) {
            b->flags |= ACNF_FLAG_OVERFLOW;
        }
        b->tx_drop = app.tx_drop;
        b->skipped = app.skipped;
        b->overflow = overflow > 0xffffu ? 0xffffu : (uint16_t)overflow;
        b->missed = app.missed;
        b->rx_lost = (uint16_t)board_rx_lost();
        if (link_send(payload, acnf_pack_block(b, payload))) {
            app.overflow_seen = overflow;
        } else {
            ++app.tx_drop; /* its samples are lost: the host counts them from the index */
        }
    }
    memset(b, 0, sizeof *b);
    b->index = app.index;
    b->run = app.run;
}

/* Compact mode: what is pending goes out now (a partial block, then a checkpoint). */
static void app_flush(void)
{
    if (app_compact() && !app.resume) {
        app_send_block();
        app_send_checkpoints(0);
    }
}

/* The compact stream pauses (stop, decimate, a mode change): flush, and remember where it ended, so
 * that the next run's checkpoints tell the host which samples before the pause were sent. */
static void app_pause(void)
{
    if (app_compact() && !app.resume) {
        app_flush();
        app.paused_at = app.index;
    }
}

static void app_reset_filters(void)
{
    acn_filters_init(&app.filters);
    app.index = 0;
    app.paused_at = 0;
    app.decim_left = 0;
    app.overflow_seen = 0;
    app.reset_pending = true;
    app.resume = true;
}

void app_init(void)
{
    unsigned ch;
    memset(&app, 0, sizeof app);
    for (ch = 0; ch < APP_NCH; ++ch) {
        link_rx_init(&app.rx[ch]);
    }
    app.decimation = 1;
    /* differs from boot to boot: re-sent power-on frames are not a reboot */
    app.run = board_boot_id();
    app.running = true; /* stream from power-on; the host may send stop */
    app_reset_filters();
}

uint32_t app_overflow_total(void)
{
    uint32_t total = 0;
    unsigned i;
    for (i = 0; i < ACNF_NAXES; ++i) {
        uint32_t o = acn_filter_overflow(&app.filters, i);
        total = (o > UINT32_MAX - total) ? UINT32_MAX : total + o;
    }
    return total;
}

APP_OUT_OF_LINE static void app_send_info(void)
{
    acnf_info_t info;
    uint8_t payload[ACNF_INFO_SIZE];
    uint32_t err = app.rx[APP_CH_HOST].errors;
#if APP_HAS_STIM
    err += app.rx[APP_CH_STIM].errors;
#endif
    info.protocol = ACNF_PROTOCOL_VERSION;
    info.layout_hash = ACNF_LAYOUT_HASH;
    info.runtime_api = ACN_RUNTIME_API;
    info.board = board_id();
    info.running = app.running ? 1u : 0u;
    info.decimation = app.decimation;
    info.rate_mhz = ACNF_RATE_MHZ;
    info.index = app.index;
    info.seq = app.seq;
    info.uptime_ms = board_time_ms();
    info.rx_errors = (uint16_t)err;
    ACN_COPY_MODEL_SHA256(info.model_sha256);
    (void)link_send(payload, acnf_pack_info(&info, payload));
}

APP_OUT_OF_LINE static void app_ack(uint8_t command, uint8_t status, uint16_t arg)
{
    acnf_ack_t ack;
    uint8_t payload[ACNF_ACK_SIZE];
    ack.command = command;
    ack.status = status;
    ack.arg = arg;
    ack.index = app.index;
    (void)link_send(payload, acnf_pack_ack(&ack, payload));
}

APP_OUT_OF_LINE static void app_command(const acnf_command_t *c)
{
    uint8_t status = ACNF_ACK_OK;
    switch (c->type) {
    case ACNF_CMD_START:
        if (!app.running) { /* seq runs on: the host sees no gap across a stop */
            app.running = true;
            app.decim_left = 0;
            app.resume = true;
        }
        break;
    case ACNF_CMD_STOP:
        app_pause();
        app.running = false;
        break;
    case ACNF_CMD_RESET:
        app_flush();
        ++app.run; /* a new run: its frames differ from the last one's even at the same index */
        app_reset_filters();
        break;
    case ACNF_CMD_DECIMATE:
        if (c->factor >= 1u && c->factor <= ACNF_MAX_DECIMATION) {
            app_pause();
            app.decimation = c->factor;
            app.decim_left = 0;
            app.resume = true;
        } else {
            status = ACNF_ACK_BAD_ARGUMENT;
        }
        break;
    case ACNF_CMD_INFO:
        app_send_info();
        break;
    case ACNF_CMD_ZUPT_BEGIN: /* a block's zupt flag holds for all its samples: a new block begins
                               */
        if (app_compact() && !app.resume) {
            app_send_block();
        }
        app.zupt = true;
        break;
    case ACNF_CMD_ZUPT_END:
        if (app_compact() && !app.resume) {
            app_send_block();
        }
        app.zupt = false;
        break;
    case ACNF_CMD_FLUSH:
        app_flush();
        break;
    case ACNF_CMD_MODE_STATES:
    case ACNF_CMD_MODE_COMPACT:
        app_pause();
        app.state_mode = c->type == ACNF_CMD_MODE_STATES;
        app.decim_left = 0;
        app.resume = true;
        break;
    default:
        status = ACNF_ACK_BAD_ARGUMENT;
        break;
    }
    app_ack(c->type, status, c->factor);
}

static uint32_t app_raw(uint32_t v)
{
    return v > ACNF_RAW_MAX ? ACNF_RAW_MAX : v;
}

/* Compact mode: before the sample app.index, begin a run (checkpoints) if one is due. */
static void app_compact_begin(void)
{
    if (app.resume) {
        uint8_t flags = ACNF_FLAG_RUNNING | ACNF_FLAG_RESUME;
        if (app.reset_pending) {
            flags |= ACNF_FLAG_RESET;
        }
        app_send_checkpoints(flags);
        memset(&app.blk, 0, sizeof app.blk);
        app.blk.index = app.index;
        app.blk.flags = flags;
        app.blk.run = app.run;
        app.resume = false;
        app.reset_pending = false;
    }
}

/* Compact mode: the sample just filtered (app.index already counts it) is in its slot; send what is
 * due. */
static void app_compact_end(void)
{
    ++app.blk.n;
    --app.ck_left;
    if (app.blk.n == ACNF_BLOCK_SAMPLES || app.ck_left == 0u) {
        app_send_block();
        if (app.ck_left == 0u) {
            app_send_checkpoints(0);
        }
    }
}

APP_OUT_OF_LINE static bool app_send_sample(const acnf_sample_t *s)
{
    uint8_t payload[ACNF_SAMPLE_SIZE];
    return link_send(payload, acnf_pack_sample(s, payload));
}

void app_sample(const acnf_stimulus_t *in)
{
    acnf_sample_t s;
    unsigned i;
    uint32_t overflow;
    bool compact = app_compact();
    unsigned slot;
    if (compact) {
        app_compact_begin();
    }
    slot = app.blk.n;
    /* input stage and filters, every sample whether streamed or not */
    for (i = 0; i < ACNF_NAXES; ++i) {
        acnf_axis_t *ax = &s.axis[i];
        memset(ax, 0, sizeof *ax);
#if ACNF_INPUT_DUTY
        ax->t1 = in->t1[i];
        ax->t2 = in->t2[i];
        if (in->flags & (1u << i)) { /* no capture: sensor unplugged; predict, flag, keep running */
            acn_filter_skip(&app.filters, i);
            ax->flags = ACNF_AXIS_TIMEOUT | ACNF_AXIS_SKIPPED;
        } else if (!acn_filter_step(&app.filters, i, in)) {
            ax->flags = ACNF_AXIS_SKIPPED;
        }
#else
        ax->code = in->code[i];
        if (!acn_filter_step(&app.filters, i, in)) { /* a rail: the generated rule */
            ax->flags = ACNF_AXIS_SKIPPED | ACNF_AXIS_RAIL;
        }
#endif
        if (ax->flags & ACNF_AXIS_SKIPPED) {
            ++app.skipped;
        }
        if (compact) {
            uint32_t code = ACNF_CODE_UPDATED;
            if (ax->flags & ACNF_AXIS_TIMEOUT) {
                code = ACNF_CODE_NO_CAPTURE;
            } else if (ax->flags & ACNF_AXIS_SKIPPED) {
                code = ACNF_CODE_REFUSED;
            }
            app.blk.aflags[slot] |= (acnf_aflags_t)(code << (2u * i));
#if ACNF_INPUT_DUTY
            app.blk.t1[i][slot] = app_raw(in->t1[i]);
            app.blk.t2[i][slot] = app_raw(in->t2[i]);
#else
            app.blk.code[i][slot] = app_raw(in->code[i]);
#endif
        } else {
            acn_filter_read(&app.filters, i, ax);
        }
    }
    s.index = app.index++;
    if (compact) {
        app_compact_end();
        return;
    }
    if (!app.running) {
        return;
    }
    if (app.decim_left > 0u) {
        --app.decim_left;
        return;
    }
    app.decim_left = (uint16_t)(app.decimation - 1u);
    overflow = app_overflow_total();
    s.seq = app.seq++;
    s.flags = ACNF_FLAG_RUNNING;
    if (app.zupt) {
        s.flags |= ACNF_FLAG_ZUPT;
    }
    if (app.reset_pending) {
        s.flags |= ACNF_FLAG_RESET;
    }
    if (overflow != app.overflow_seen) {
        s.flags |= ACNF_FLAG_OVERFLOW;
    }
    s.tx_drop = app.tx_drop;
    s.skipped = app.skipped;
    s.overflow = overflow > 0xffffu ? 0xffffu : (uint16_t)overflow;
    s.missed = app.missed;
    s.rx_lost = (uint16_t)board_rx_lost();
    if (app_send_sample(&s)) {
        app.reset_pending = false;
        app.overflow_seen = overflow;
    } else {
        ++app.tx_drop; /* its seq is spent: the host counts it lost, tx_drop says why */
    }
}

void app_missed(uint32_t n)
{
    unsigned i;
    for (; n > 0u; --n) {
        bool compact = app_compact();
        if (compact) {
            app_compact_begin();
        }
        for (i = 0; i < ACNF_NAXES; ++i) {
            acn_filter_skip(&app.filters, i); /* predict only: x = F x + b, P = F P F' + Q */
            if (compact) {
                app.blk.aflags[app.blk.n] |= (acnf_aflags_t)(ACNF_CODE_MISSED << (2u * i));
            }
        }
        ++app.index;
        ++app.missed;
        if (compact) {
            app_compact_end();
        }
    }
}

void app_rx(unsigned ch, const uint8_t *p, size_t n)
{
    link_rx_t *rx;
    size_t k;
    if (ch >= APP_NCH) {
        return;
    }
    rx = &app.rx[ch];
    for (k = 0; k < n; ++k) {
        size_t len = link_rx_byte(rx, p[k]);
        acnf_command_t c;
        acnf_stimulus_t t;
        if (len == 0u) {
            continue;
        }
        if (acnf_parse_stimulus(rx->buf, len, &t)) {
            app_sample(&t);
        } else if (acnf_parse_command(rx->buf, len, &c)) {
            app_command(&c);
        } else {
            ++rx->errors;
        }
    }
}
