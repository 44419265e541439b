#include "filter_adapter.h"

#if ACNF_COMPACT
/* the frame layout's checkpoint sizes (filter manifest) must be the generated filter's, or no build
 * (accelnav_<axis>_save writes ACCELNAV_<AXIS>_CK_BYTES bytes, whatever the struct's layout) */
#define ACN_SIZE_CHECK(name, NAME, i)                                                              \
    typedef char acn_state_size_##name[ACCELNAV_##NAME##_CK_BYTES == ACNF_STATE_BYTES_##i ? 1 : -1];
ACNF_AXES(ACN_SIZE_CHECK)
#endif

const uint8_t acn_model_sha256[32] ACN_SHA_FLASH = ACNF_MODEL_SHA256_BYTES;

#define ACN_INIT(name, NAME, i) accelnav_##name##_init(&f->name);
void acn_filters_init(acn_filters_t *f)
{
    ACNF_AXES(ACN_INIT)
}

#if ACNF_INPUT_DUTY
/* capture counts above INT32_MAX are no period the filter accepts; keep them invalid */
static int32_t acn_count(uint32_t c)
{
    return c > (uint32_t)INT32_MAX ? INT32_MAX : (int32_t)c;
}
#define ACN_STEP(name, NAME, i)                                                                    \
    case i:                                                                                        \
        return accelnav_##name##_step(&f->name, acn_count(in->t1[i]), acn_count(in->t2[i]));
#else
#define ACN_STEP(name, NAME, i)                                                                    \
    case i:                                                                                        \
        return accelnav_##name##_step(&f->name, (int32_t)in->code[i]);
#endif

bool acn_filter_step(acn_filters_t *f, unsigned i, const acnf_stimulus_t *in)
{
    switch (i) {
        ACNF_AXES(ACN_STEP)
    default:
        return false;
    }
}

#define ACN_SKIP(name, NAME, i)                                                                    \
    case i:                                                                                        \
        accelnav_##name##_skip(&f->name);                                                          \
        break;
void acn_filter_skip(acn_filters_t *f, unsigned i)
{
    switch (i) {
        ACNF_AXES(ACN_SKIP)
    default:
        break;
    }
}

#define ACN_READ(name, NAME, i)                                                                    \
    case i: {                                                                                      \
        accelnav_##name##_out_t o;                                                                 \
        accelnav_##name##_read(&f->name, &o);                                                      \
        out->r = o.r;                                                                              \
        out->u = o.u;                                                                              \
        out->a = o.a;                                                                              \
        out->e = o.e;                                                                              \
        break;                                                                                     \
    }
void acn_filter_read(const acn_filters_t *f, unsigned i, acnf_axis_t *out)
{
    switch (i) {
        ACNF_AXES(ACN_READ)
    default:
        break;
    }
}

#define ACN_STATE(name, NAME, i)                                                                   \
    case i:                                                                                        \
        accelnav_##name##_save(&f->name, out);                                                     \
        break;
void acn_filter_state(const acn_filters_t *f, unsigned i, uint8_t *out)
{
#if ACNF_COMPACT
    switch (i) {
        ACNF_AXES(ACN_STATE)
    default:
        break;
    }
#else /* no checkpoints: the filter has no checkpoint image (the float32 variant) */
    (void)f;
    (void)i;
    (void)out;
#endif
}

#define ACN_OVF(name, NAME, i)                                                                     \
    case i:                                                                                        \
        return f->name.overflow;
uint32_t acn_filter_overflow(const acn_filters_t *f, unsigned i)
{
    switch (i) {
        ACNF_AXES(ACN_OVF)
    default:
        return 0;
    }
}
