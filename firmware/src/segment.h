/* Move segment wire decoding with the per-session coder context. */
#ifndef SEGMENT_H
#define SEGMENT_H
#include <stdint.h>
#include "wire.h"

struct seg_ctx {
    uint32_t prev_ticks;
    int32_t prev_deltas[4];
};

struct segment {
    uint32_t ticks;
    int32_t deltas[4];
    int16_t ramp; /* -1: constant speed */
};

/* Decode the segment whose opcode is at r->pos; sets r->err on any bad field. */
void segment_decode(struct reader *r, struct seg_ctx *ctx, struct segment *out);

#endif
