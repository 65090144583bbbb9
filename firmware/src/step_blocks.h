/* The schedule blocks' chunks of the queued segments, kept for the step engine
 * (PROTOCOL.md 5.5; schedule_block.h reads them).
 *
 * One ring of chunks shared by the queue's segments: the command layer reads a segment's
 * block straight into it (blocks_sink) as it queues the segment, the segment's item keeps
 * where its block lies (blocks_commit), and the step tick frees a segment's chunks once
 * the steppers are past them (blocks_release). A block takes one run of entries (a
 * block never wraps: the end of the ring is skipped when the block does not fit before
 * it), for each of its axes a header (count: the axis's chunks, interval: its first edge
 * from the segment's start) and then the chunks. The engine reads a chunk when it starts
 * it; its first edge is where the last chunk left off (the recurrence's T after its last
 * edge), so no time is kept per chunk. */
#ifndef STEP_BLOCKS_H
#define STEP_BLOCKS_H
#include <stdint.h>

#include "config.h"
#include "queue.h"
#include "schedule_block.h"

#if STEP_ENGINE
#define BLOCK_CHUNKS 128 /* entries (a power of two, at most 128): 10 bytes each */
#else
#define BLOCK_CHUNKS 1 /* the tick's DDA steps every axis: blocks are checked, not kept */
#endif
/* the most entries a block in B bytes (from its segment's opcode) can take: a header and
 * a first chunk of at least 4 bytes an axis (a axes), 3 bytes each further chunk, after
 * the opcode and the mask: 2 a + (B - 2 - 4 a) / 3 <= (B + 6) / 3 */
#define BLOCK_ENTRIES(bytes) (((bytes) + 6) / 3)
#define BLOCK_MOST BLOCK_ENTRIES(DEV_MAX_PAYLOAD)

extern struct sched_chunk block_chunks[BLOCK_CHUNKS];

/* The sink to read the next block into (main loop): the free entries from the ring's
 * head on, up to its end or its tail (`capacity`), or 0 while there is no room. `need`:
 * the entries the block takes once known (blocks_sink_short), else 0. A block known not
 * to fit before the ring's end is placed at its start (the end skipped); the sink is 0,
 * and blocks_stalled set, while the ring has no room for it (the steppers free it as
 * they go: a machine at rest starts, PROTOCOL.md 5.4). Only what the block takes is
 * reserved, not what the rest of its frame could hold. */
struct sched_block *blocks_sink(uint8_t need);
/* Whether a block of `need` entries would be placed now without a wait (the step engine
 * only). */
uint8_t blocks_fit(uint8_t need);
/* After a block was read into the sink: the entries it takes when that is more than the
 * sink held (its chunks were not kept: read it again into blocks_sink(that)), else 0. */
uint8_t blocks_sink_short(void);
extern volatile uint8_t blocks_stalled;
/* The block just read into the sink belongs to item `it` (queued): its entries are
 * kept until the item's segment is done. */
void blocks_commit(struct item *it);
/* Free the entries before `end` (an item's blk_end; the step interrupt). */
static inline void blocks_release(uint8_t end);
/* Forget every block (the queue was flushed; interrupts off). */
void blocks_reset(void);

extern volatile uint8_t blocks_head, blocks_tail; /* counters modulo 256 */
/* The entries the queued segments' blocks hold (a skipped end counted with them). */
static inline uint8_t blocks_used(void)
{
    return (uint8_t)(blocks_head - blocks_tail);
}
static inline void blocks_release(uint8_t end)
{
    blocks_tail = end;
}

#endif
