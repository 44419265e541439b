/* The application: input stage, filters, telemetry, commands. Board-independent.
 * Its entry points (app_init, app_sample, app_rx) are declared in board.h;
 * this header adds what tests and boards may inspect. */
#ifndef ACN_APP_H
#define ACN_APP_H

#include <stdbool.h>
#include <stdint.h>

#include "acn_board.h"
#include "filter_adapter.h"
#include "link.h"

typedef struct {
    acn_filters_t filters;
    link_rx_t rx[APP_NCH];
    uint32_t index;      /* samples since reset */
    uint16_t run;        /* run id: the board's boot id, plus one per reset command */
    uint32_t paused_at;  /* index where the compact stream last paused (0 after a reset) */
    uint16_t seq;        /* sample frames attempted since start */
    uint16_t decimation; /* 1: compact block frames; 2..ACNF_MAX_DECIMATION: sample frames */
    uint16_t decim_left; /* samples until the next frame */
    uint16_t tx_drop;
    uint16_t skipped;
    uint16_t missed;        /* samples missed by the board and predicted over */
    uint32_t overflow_seen; /* saturation total at the last frame */
    bool running;
    bool zupt;
    bool reset_pending; /* flag the next frame */
    /* compact mode (decimation 1) */
    acnf_block_t blk; /* the block being filled; blk.index: its first sample */
    uint32_t ck_left; /* samples until the next checkpoint */
    bool resume;      /* the next sample begins a compact run: checkpoints first */
    bool state_mode;  /* sample frames at decimation 1 too (command mode_states) */
} app_state_t;

extern app_state_t app;

/* Total filter saturations of every axis (saturating at UINT32_MAX). */
uint32_t app_overflow_total(void);

#endif
