/* Extras of the host board, for tests driving it in-process. */
#ifndef ACN_BOARD_HOST_H
#define ACN_BOARD_HOST_H

#include <stddef.h>
#include <stdint.h>

/* Move up to max queued telemetry bytes to out; returns how many. */
size_t board_host_take(uint8_t *out, size_t max);

/* Pretend the link buffer holds only limit bytes (to exercise dropped frames). */
void board_host_set_tx_limit(size_t limit);

/* What board_boot_id() returns from the next app_init on (a power-on of another boot). */
void board_host_set_boot_id(uint16_t id);

#endif
