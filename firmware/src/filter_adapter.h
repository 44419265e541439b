/* The one place that knows the generated filter's API (build/.../accelnav.h).
 * If the generator's API shifts, this file and filter_adapter.c change, nothing else. */
#ifndef ACN_FILTER_ADAPTER_H
#define ACN_FILTER_ADAPTER_H

#include <stdbool.h>
#include <stdint.h>

#include "acnframe.h"
#include "accelnav.h"

/* The generated API this adapter is written against (2: the checkpoint image,
 * accelnav_<axis>_save). */
#if ACCELNAV_RUNTIME_API != 2
#error "accelnav.h is from another runtime API: regenerate it with this accelnav (accelnav codegen)"
#endif

#define ACN_STATE_MEMBER(name, NAME, i) accelnav_##name##_t name;
typedef struct {
    ACNF_AXES(ACN_STATE_MEMBER)
} acn_filters_t;
#undef ACN_STATE_MEMBER

void acn_filters_init(acn_filters_t *f);

/* One sample of axis i from its raw input: true when updated, false when the
 * input was refused (rail, invalid capture) and only a prediction was made. */
bool acn_filter_step(acn_filters_t *f, unsigned i, const acnf_stimulus_t *in);

/* Predict only (no capture at all). */
void acn_filter_skip(acn_filters_t *f, unsigned i);

/* The state of axis i in its fixed-point formats, into the frame's axis record. */
void acn_filter_read(const acn_filters_t *f, unsigned i, acnf_axis_t *out);

/* Axis i's state as its checkpoint image (accelnav_<axis>_save: ACNF_STATE_BYTES_<i> bytes) into
 * out, for a checkpoint. */
void acn_filter_state(const acn_filters_t *f, unsigned i, uint8_t *out);

/* Saturations counted by the filter of axis i since init. */
uint32_t acn_filter_overflow(const acn_filters_t *f, unsigned i);

/* 32-byte model hash and runtime API of the generated filter. On the AVR the hash stays in flash
 * (32 B of RAM otherwise): ACN_COPY_MODEL_SHA256 copies it out wherever it lives. */
#if defined(__AVR__)
#include <avr/pgmspace.h>
#define ACN_SHA_FLASH PROGMEM
#define ACN_COPY_MODEL_SHA256(dst) memcpy_P((dst), acn_model_sha256, 32u)
#else
#define ACN_SHA_FLASH
#define ACN_COPY_MODEL_SHA256(dst) memcpy((dst), acn_model_sha256, 32u)
#endif
extern const uint8_t acn_model_sha256[32] ACN_SHA_FLASH;
#define ACN_RUNTIME_API ACCELNAV_RUNTIME_API

#endif
