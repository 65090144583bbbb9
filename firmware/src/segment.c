#include "protocol_gen.h"
#include "segment.h"

void segment_decode(struct reader *r, struct seg_ctx *ctx, struct segment *out)
{
    uint8_t op = rd_u8(r);
    int32_t coded[4] = {0, 0, 0, 0};
    if (op & SEG_F_RESERVED)
        r->err = 1;
    out->ticks = (op & SEG_F_DURATION) ? rd_uv(r) : ctx->prev_ticks;
    if (out->ticks == 0)
        r->err = 1;
    if (op & SEG_F_SLIDERS)
        for (uint8_t k = 0; k < 3; k++)
            coded[k] = rd_sv(r);
    if (op & SEG_F_EXTRUDER)
        coded[3] = rd_sv(r);
    for (uint8_t k = 0; k < 4; k++) {
        if (op & SEG_F_PREDICTED) {
            int64_t d = (int64_t)coded[k] + ctx->prev_deltas[k];
            if (d > SEG_MAX_DELTA || d < -SEG_MAX_DELTA)
                r->err = 1;
            coded[k] = (int32_t)d;
        } else if (coded[k] < -SEG_MAX_DELTA) {
            r->err = 1;
        }
        out->deltas[k] = coded[k];
    }
    out->ramp = (op & SEG_F_RAMP) ? rd_u8(r) : SEG_RAMP_CONSTANT;
    if (r->err)
        return;
    ctx->prev_ticks = out->ticks;
    for (uint8_t k = 0; k < 4; k++)
        ctx->prev_deltas[k] = out->deltas[k];
}
