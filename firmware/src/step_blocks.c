/* The ring of the schedule blocks' chunks (step_blocks.h). */
#include <avr/interrupt.h>

#include "step_blocks.h"
#include "step_engine.h"

_Static_assert((BLOCK_CHUNKS & (BLOCK_CHUNKS - 1)) == 0 && BLOCK_CHUNKS <= 128,
               "BLOCK_CHUNKS: a power of two, its counters modulo 256");
_Static_assert(!STEP_ENGINE || BLOCK_MOST <= BLOCK_CHUNKS / 2, "two blocks of the most in the ring");

#if STEP_ENGINE
struct sched_chunk block_chunks[BLOCK_CHUNKS];
#endif
volatile uint8_t blocks_head, blocks_tail, blocks_stalled;
#if STEP_ENGINE
static struct sched_block sink;
#endif

#if STEP_ENGINE
/* Where a block of `want` entries goes: the counter of its first entry into *at and the
 * free run from there into *run; 0 while it would wait (the rule the host follows too,
 * firmware_protocol/block_ring.py) */
static uint8_t place(uint8_t want, uint8_t *at, uint8_t *run)
{
    uint8_t head = blocks_head, tail = blocks_tail;
    uint8_t free = (uint8_t)(BLOCK_CHUNKS - (uint8_t)(head - tail));
    uint8_t to_end = (uint8_t)(BLOCK_CHUNKS - (head & (BLOCK_CHUNKS - 1)));
    uint8_t r = free < to_end ? free : to_end; /* free entries from the head on */
    if (want > r) {
        /* at the ring's start, the end skipped (freed with the block after it), when the
         * block does not fit before the end and fits after it */
        if (r < free && want <= (uint8_t)(free - to_end)) {
            head = (uint8_t)(head + to_end);
            r = (uint8_t)(free - to_end);
        } else {
            return 0;
        }
    }
    *at = head;
    *run = r;
    return 1;
}

uint8_t blocks_fit(uint8_t need)
{
    uint8_t at, run;
    return place(need, &at, &run);
}
#endif

struct sched_block *blocks_sink(uint8_t need)
{
#if STEP_ENGINE
    uint8_t head, run;
    /* unknown: at least an axis's header and chunk */
    if (!place(need ? need : 2, &head, &run)) {
        blocks_stalled = 1;
        return 0;
    }
    blocks_stalled = 0;
    blocks_head = head;
    sink.chunk = &block_chunks[head & (BLOCK_CHUNKS - 1)];
    sink.capacity = run;
    sink.used = 0;
    sink.mask = 0;
    return &sink;
#else
    (void)need;
    return 0;
#endif
}

#if STEP_ENGINE
uint8_t blocks_sink_short(void)
{
    return sink.used > sink.capacity ? sink.used : 0;
}
#endif

void blocks_commit(struct item *it)
{
#if STEP_ENGINE
    uint8_t head = blocks_head;
    /* the chunks the engine's assembly may not run (step_chunk_slow) marked for C: bit 31
     * of the interval (a block's intervals are under 2^31) */
    struct sched_chunk *c = sink.chunk, *end = c + sink.used;
    while (c < end) {
        uint8_t n = (uint8_t)c->count; /* the axis's header */
        for (c++; n; n--, c++)
            if (step_chunk_slow(c->interval, c->add, c->count))
                c->interval |= 0x80000000UL;
    }
    it->blk_at = head & (BLOCK_CHUNKS - 1);
    it->blk_mask = sink.mask;
    head = (uint8_t)(head + sink.used);
    it->blk_end = head;
    blocks_head = head;
#else
    (void)it;
#endif
}

void blocks_reset(void)
{
    blocks_tail = blocks_head;
    blocks_stalled = 0;
}
