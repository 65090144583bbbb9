/* Move segment wire decoding with the per-session coder context. */
#ifndef SEGMENT_H
#define SEGMENT_H
#include <stdint.h>
#include "protocol_gen.h"
#include "schedule_block.h"
#include "wire.h"

struct seg_ctx {
    uint32_t prev_ticks;
    int32_t prev_deltas[4];
};

struct segment {
    uint32_t ticks;
    int32_t deltas[4];
    int16_t ramp;                /* -1: constant speed */
    struct sched_verdict sched; /* its schedule block's axes and verdict (mask 0: none) */
};

/* Where segment_decode reads a schedule block's chunks (the step engine's ring while a
 * segment is decoded to be queued, step_blocks.h); 0: checked only. */
extern struct sched_block *segment_sched_out;

/* Decode the segment whose opcode is at r->pos; sets r->err on any bad field. */
void segment_decode_full(struct reader *r, struct seg_ctx *ctx, struct segment *out);

/* The same, inline for a segment that is its opcode alone: the duration and the
 * deltas of the one before (predicted, nothing coded) or no motion (a pause), at
 * constant speed. A print's straight lines cut into short segments are mostly
 * these. The context's values are valid (only a valid segment stores them), so
 * only a first segment without a duration is an error. */
static inline __attribute__((always_inline)) void segment_decode(struct reader *r,
                                                                 struct seg_ctx *ctx,
                                                                 struct segment *out)
{
    uint8_t op = r->buf[r->pos];
    if ((op & ~SEG_F_PREDICTED) != SEG_BASE || !ctx->prev_ticks) {
        segment_decode_full(r, ctx, out);
        return;
    }
    r->pos++;
    out->ticks = ctx->prev_ticks;
    out->ramp = SEG_RAMP_CONSTANT;
    out->sched.mask = 0;
    if (op & SEG_F_PREDICTED) {
        for (uint8_t k = 0; k < 4; k++)
            out->deltas[k] = ctx->prev_deltas[k];
    } else {
        for (uint8_t k = 0; k < 4; k++)
            out->deltas[k] = ctx->prev_deltas[k] = 0;
    }
}

#endif
