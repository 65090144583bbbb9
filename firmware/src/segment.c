#include <stdint.h>

#include "protocol_gen.h"
#include "segment.h"

struct sched_block *segment_sched_out;
uint8_t segment_form_only;

/* A coded delta: an i32 (zigzag u32, at most 5 bytes). Inline for the one-byte
 * case (a print's small corrections to the predicted deltas): the call and the
 * 32-bit zigzag cost more than the rest of the segment. */
static inline __attribute__((always_inline)) int32_t rd_delta(struct reader *r)
{
    uint8_t pos = r->pos;
    if (pos < r->len) {
        uint8_t b = r->buf[pos];
        if (!(b & 0x80)) {
            r->pos = (uint8_t)(pos + 1);
            return (int8_t)((b >> 1) ^ (uint8_t)-(b & 1));
        }
    }
    return unzigzag(rd_bounded(r, 32));
}

/* One axis: the coded value, plus the previous delta when predicted; within
 * -(2^31 - 1)..2^31 - 1, in 32-bit arithmetic. */
static inline __attribute__((always_inline)) int32_t axis_delta(struct reader *r, int32_t coded,
                                                                 uint8_t predicted, int32_t prev)
{
    int32_t d = coded;
    if (predicted && __builtin_add_overflow(coded, prev, &d))
        r->err = 1;
    if (d == INT32_MIN)
        r->err = 1;
    return d;
}

/* |d| of a delta within -(2^31 - 1)..2^31 - 1 */
static inline uint32_t magnitude(int32_t d)
{
    return (uint32_t)(d < 0 ? -d : d);
}

/* Called twice for every segment (checked on arrival, decoded again to execute),
 * thousands of times a second: straight-line code, no arrays, optimized for speed. */
void __attribute__((optimize("O2"))) segment_decode_full(struct reader *r, struct seg_ctx *ctx,
                                                         struct segment *out)
{
    uint8_t op = r->buf[r->pos++]; /* the caller saw it */
    if (op & SEG_F_RESERVED) {
        r->err = 1;
        return;
    }
    uint32_t ticks = ctx->prev_ticks;
    if (op & SEG_F_DURATION) {
        uint8_t pos = r->pos;
        if (pos < r->len && !(r->buf[pos] & 0x80)) {
            ticks = r->buf[pos];
            r->pos = (uint8_t)(pos + 1);
        } else {
            ticks = rd_bounded(r, 32);
        }
    }
    if (ticks == 0)
        r->err = 1;
    int32_t c0 = 0, c1 = 0, c2 = 0, c3 = 0;
    if (op & SEG_F_SLIDERS) {
        c0 = rd_delta(r);
        c1 = rd_delta(r);
        c2 = rd_delta(r);
    }
    if (op & SEG_F_EXTRUDER)
        c3 = rd_delta(r);
    uint8_t predicted = op & SEG_F_PREDICTED;
    int32_t d0 = axis_delta(r, c0, predicted, ctx->prev_deltas[0]);
    int32_t d1 = axis_delta(r, c1, predicted, ctx->prev_deltas[1]);
    int32_t d2 = axis_delta(r, c2, predicted, ctx->prev_deltas[2]);
    int32_t d3 = axis_delta(r, c3, predicted, ctx->prev_deltas[3]);
    int16_t ramp = SEG_RAMP_CONSTANT;
    if (op & SEG_F_RAMP) {
        if (r->pos >= r->len)
            r->err = 1;
        else
            ramp = r->buf[r->pos++];
    }
    out->sched.mask = 0;
    if ((op & SEG_F_SCHEDULE) && !r->err) {
        if (segment_form_only) {
            sched_skip(r);
        } else {
            uint32_t steps[4] = {magnitude(d0), magnitude(d1), magnitude(d2), magnitude(d3)};
            sched_parse(r, ticks, steps, &out->sched, segment_sched_out);
        }
    }
    if (r->err)
        return;
    out->ticks = ctx->prev_ticks = ticks;
    out->deltas[0] = ctx->prev_deltas[0] = d0;
    out->deltas[1] = ctx->prev_deltas[1] = d1;
    out->deltas[2] = ctx->prev_deltas[2] = d2;
    out->deltas[3] = ctx->prev_deltas[3] = d3;
    out->ramp = ramp;
}
