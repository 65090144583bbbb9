/* A segment's schedule block (protocol 3.0, PROTOCOL.md 5.5): the step schedules of the
 * axes the device cannot predict, each a first edge and chunks (count, interval, add) in
 * fixed point of a CPU cycle (CDPR_SCHED_FRAC_BITS).
 *
 * A frame's check on receipt reads each block's form only (sched_skip: a malformed block
 * is r->err, BAD_COMMAND, and nothing of the frame runs). sched_parse reads it once more
 * as its segment is queued: its form again and, in the same pass, what it says of its
 * segment (the verdict: BAD_VALUE, nothing of the segment queued): the counts add up to
 * |n| (the first chunk takes what the others leave, at least 1), every count 1..65535,
 * every interval 1..2^31 - 1, the first edge not before the segment, no interval under
 * MIN_STEP_INTERVAL_CYCLES; all in 32-bit arithmetic (the ranges are in
 * schedule_block.c). It keeps O(1) state and no copy of the block; a caller that wants
 * the chunks (the step engine) passes a struct sched_block to fill. Today's DDA keeps its
 * own edges within the same tolerance of the same ideal edges, so nothing else reads
 * them yet. */
#ifndef SCHEDULE_BLOCK_H
#define SCHEDULE_BLOCK_H
#include <stdint.h>
#include "config.h"
#include "protocol_gen.h"
#include "wire.h"

struct sched_chunk {
    uint16_t count;
    uint32_t interval; /* fixed point */
    int32_t add;
};

/* One block's chunks for the step engine; `capacity` entries in `chunk`, filled in axis
 * order: for each axis of `mask` a header (its count the axis's chunks, its interval the
 * first edge, `lead`) and then its chunks (`first[k]` the header's index, `chunks[k]`
 * the chunks after it); `used` the entries filled. With the step engine a block that
 * needs more than `capacity` is not an error: it is read to its end, none of its
 * chunks kept, and `used` says how many entries it takes (more than `capacity`). */
struct sched_block {
    uint8_t mask;
    uint32_t lead[CDPR_SCHED_AXES]; /* first edge, fixed point, from the segment's start */
    uint8_t first[CDPR_SCHED_AXES];
    uint8_t chunks[CDPR_SCHED_AXES];
    uint8_t capacity;
    uint8_t used;
    struct sched_chunk *chunk;
};

/* What a block says of its segment: `axis` -1 when it runs, else the axis refused and
 * `value` why (the first chunk's count, an out-of-range count, interval or first edge,
 * the shortest interval in cycles). */
struct sched_verdict {
    uint8_t mask; /* axes it carries */
    int8_t axis;
    int32_t value;
};

/* The block at r->pos for a segment of `ticks` ticks and |n| `steps`; sets r->err when it
 * is malformed (or, without the step engine, when `out` has no room for its chunks).
 * `out` may be NULL. */
void sched_parse(struct reader *r, uint32_t ticks, const uint32_t steps[CDPR_SCHED_AXES],
                 struct sched_verdict *verdict, struct sched_block *out);

/* The block at r->pos read past, its form checked as sched_parse checks it (r->err), what
 * it says of its segment not: a frame's check on receipt, whose segments are queued (and
 * their blocks' verdicts taken, sched_parse) only when the frame is executed. */
void sched_skip(struct reader *r);

#endif
