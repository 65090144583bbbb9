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
/* 1 while a frame is checked on receipt (check_payload): a schedule block's form only
 * (sched_skip), its verdict (sched_parse) taken once, when the segment is queued. */
extern uint8_t segment_form_only;

/* Decode the segment whose opcode is at r->pos; sets r->err on any bad field. */
void segment_decode_full(struct reader *r, struct seg_ctx *ctx, struct segment *out);

/* A segment of a print's curve: the modules' deltas (and the extruder's) coded plain,
 * each in one byte (|delta| < 64), the duration of the one before, constant speed:
 * most segments of a print at 2,000 segments/s (94 % of bench/stream_rates.py's), here
 * in about 100 cycles where the full decoder's call and frame cost about 470. 1 when the
 * segment at r->pos was one (decoded), 0 when the full decoder must decode it. */
static inline __attribute__((always_inline)) uint8_t segment_decode_plain(struct reader *r,
                                                                          struct seg_ctx *ctx,
                                                                          struct segment *out,
                                                                          uint8_t op)
{
    if ((op & ~SEG_F_EXTRUDER) != (SEG_BASE | SEG_F_SLIDERS) || !ctx->prev_ticks)
        return 0;
    uint8_t n = (op & SEG_F_EXTRUDER) ? 4 : 3, pos = r->pos;
    if ((uint8_t)(r->len - pos) <= n)
        return 0; /* the opcode and n codes do not fit: the full decoder says so */
    const uint8_t *c = r->buf + pos + 1;
    if ((c[0] | c[1] | c[2] | (n == 4 ? c[3] : 0)) & 0x80)
        return 0; /* a longer code */
    for (uint8_t k = 0; k < 4; k++) {
        uint8_t b = k < n ? c[k] : 0;
        int32_t d = (int8_t)((b >> 1) ^ (uint8_t)-(b & 1)); /* zigzag */
        out->deltas[k] = ctx->prev_deltas[k] = d;
    }
    r->pos = (uint8_t)(pos + 1 + n);
    out->ticks = ctx->prev_ticks;
    out->ramp = SEG_RAMP_CONSTANT;
    out->sched.mask = 0;
    return 1;
}

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
    if (segment_decode_plain(r, ctx, out, op))
        return;
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
