#include <stdint.h>

#include "protocol_gen.h"
#include "segment.h"

/* A coded delta: an i32 (zigzag u32, at most 5 bytes). */
static int32_t rd_delta(struct reader *r)
{
    return unzigzag(rd_bounded(r, 32));
}

void segment_decode(struct reader *r, struct seg_ctx *ctx, struct segment *out)
{
    uint8_t op = rd_u8(r);
    int32_t coded[4] = {0, 0, 0, 0};
    if (op & SEG_F_RESERVED)
        r->err = 1;
    out->ticks = (op & SEG_F_DURATION) ? rd_bounded(r, 32) : ctx->prev_ticks;
    if (out->ticks == 0)
        r->err = 1;
    if (op & SEG_F_SLIDERS)
        for (uint8_t k = 0; k < 3; k++)
            coded[k] = rd_delta(r);
    if (op & SEG_F_EXTRUDER)
        coded[3] = rd_delta(r);
    for (uint8_t k = 0; k < 4; k++) {
        int32_t d = coded[k];
        /* within -(2^31 - 1)..2^31 - 1, in 32-bit arithmetic */
        if ((op & SEG_F_PREDICTED) && __builtin_add_overflow(d, ctx->prev_deltas[k], &d))
            r->err = 1;
        if (d == INT32_MIN)
            r->err = 1;
        out->deltas[k] = d;
    }
    out->ramp = (op & SEG_F_RAMP) ? rd_u8(r) : SEG_RAMP_CONSTANT;
    if (r->err)
        return;
    ctx->prev_ticks = out->ticks;
    for (uint8_t k = 0; k < 4; k++)
        ctx->prev_deltas[k] = out->deltas[k];
}
