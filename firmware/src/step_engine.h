/* The step engine: one timer compare event per step edge, per stepper.
 *
 * Each stepper has its own output-compare channel on a 16-bit timer clocked at the CPU's
 * 16 MHz: the modules X, Y, Z on Timer3 A, B, C, the extruder on Timer5 A; Timer3 and
 * Timer5 run in step (started together) and the step tick's boundaries (Timer1) are
 * known on their time base. A stepper runs chunks: `count` edges, the first at `t`, each
 * next one `interval` later (times fixed point, STEP_FRAC_BITS fraction bits of a cycle,
 * modulo 2^24 cycles), so its interrupt only adds: edge at T; T += I; if --count == 0
 * take the next chunk from the stepper's ring. The tick's computation (stepper.c) puts
 * a constant-speed segment's axis in one chunk at the segment's start, its interval
 * predicted from the reciprocal table (step_recip.h), which the host mirrors.
 *
 * Stage 1 of docs/step-engine.md section 6 (built only with STEP_ENGINE=1, config.h;
 * figures in firmware/README.md, `python firmware/tools/engine_rates.py`): the common
 * edge in assembly, a chunk's rare cases in C; the 400 us tick still runs beside it as
 * the segment clock (queue items, markers, the record) and steps the ramps from its time
 * wheel. */
#ifndef STEP_ENGINE_H
#define STEP_ENGINE_H
#include <stdint.h>

#include "mul16.h"

#define STEP_FRAC_BITS 8
#define CHUNK_SLOTS 1 /* a power of two: the chunks of a stepper queued ahead for C (the
                       * assembly's next two chunks have slots of their own) */

struct sched_chunk;
/* (the layout is the assembly's: it reads a stepper's waiting chunk by offset) */
struct step_chunk {
    uint32_t t;        /* the first edge, Q24.8 cycles on the steppers' time base */
    uint32_t interval; /* Q24.8 cycles between its first two edges */
    uint16_t count;    /* edges, >= 1 */
    uint8_t neg;       /* the direction: 1 toward negative steps */
    int32_t add;       /* added to the interval at each edge (a ramp's; 0: steady) */
    /* a schedule block's further chunks, run after this one (step_blocks.h): each starts
     * where the one before left off */
    uint8_t nblk;
    const struct sched_chunk *blk;
};

/* The steppers' clock: Timer3's count extended to 24 bits, Q24.8 (the start of the tick
 * being computed, for the tick's computation). */
extern uint32_t step_clock_next_tick;
extern uint32_t step_clock_this_tick; /* the start of the tick in progress */

/* Timers 3 and 5 started in step with Timer1's ticks (called by step_timer_init with
 * interrupts off, Timer1 stopped and zeroed; it starts Timer1 too). */
void step_engine_start_timers(uint8_t timer1_b);

/* Queue a chunk for stepper k (interrupts on or off); it runs after the chunks before
 * it. Returns 0 when nothing can take it: next and the ring both hold a chunk. A tick
 * puts a segment's chunks out at most two segments ahead of the running chunk (segments
 * shorter than a tick: the one in next, this one), so the ring's chunk moves up into next
 * as soon as next is free and this one takes the ring; the caller stops (PLANNER_LATE)
 * rather than lose its steps. */
uint8_t step_engine_push(uint8_t k, const struct step_chunk *c);
/* A segment's steady chunks in one pass, the tick's common case: the ones the assembly
 * runs (add 0, no block) straight to where it takes them, at a third of a push's cycles.
 * Stepper k of `mask` (bit k) makes |n[k]|
 * edges toward n[k]'s sign, the first half its interval after `start`, its interval (Q24.8)
 * the uint32_t at interval_at + k * STEP_STEADY_STRIDE (the caller's layout: the plan's
 * axes, stepper.c). Returns the steppers of `mask` it could not place so (stopped, a
 * chunk in the ring, an interval of 2^15 cycles or more): push those. */
#define STEP_STEADY_STRIDE 23
uint8_t step_engine_push_steadies(uint32_t start, uint8_t mask, const uint8_t *interval_at,
                                  const int32_t *n);

/* Whether the assembly may not run a chunk (C does): its intervals, the last one too,
 * of 2^15 cycles or more (its lateness test compares 16-bit times). The body inline where
 * a call would deepen the step tick's deepest path (start_axis: tools/stack_usage.py);
 * out of line elsewhere (inline in the steppers' C paths too, their module 3's edge at a
 * ramp's end came 2.5 us later: tests/firmware/test_step_timing.py's 25 us crossed). */
static inline __attribute__((always_inline)) uint8_t step_chunk_slow_here(uint32_t interval,
                                                                          int32_t add,
                                                                          uint16_t count)
{
    uint32_t longest = interval;
    if (add > 0 && count > 1) {
        if ((uint32_t)add >= 0x800000UL)
            return 1;
        uint16_t n = (uint16_t)(count - 1);
        uint32_t grow = mul16x16((uint16_t)(add >> 8), n); /* < 2^15 2^16 */
        if (grow >= 0x8000UL)
            return 1;
        longest += (grow << 8) + mul16x16((uint8_t)add, n);
    }
    return longest >= 0x800000UL;
}

static inline uint8_t step_chunk_slow(uint32_t interval, int32_t add, uint16_t count)
{
    return step_chunk_slow_here(interval, add, count);
}

/* No stepper runs and none has a chunk waiting. */
uint8_t step_engine_idle(void);

/* Stepper k's edges queued and not raised yet (its running chunk's, the armed one
 * included, and its waiting chunks'), signed by their direction: with interrupts off,
 * before step_engine_stop, a halt's positions count the edges issued. */
int32_t step_engine_unissued(uint8_t k);

/* Stop every stepper now and forget their chunks (halt, flush). */
void step_engine_stop(void);


/* edges armed after their time had passed (late by more than the arming margin) */
extern volatile uint16_t step_engine_late;

#endif
