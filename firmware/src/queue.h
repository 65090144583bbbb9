/* The move queue and the plans prepared ahead of the step interrupt.
 *
 * Queue: items executed strictly in order by the step interrupt. The main loop
 * appends at head; the interrupt completes at tail. An item keeps its slot while
 * it executes (the protocol counts it as not free). Segments are stored as
 * decoded (duration, step counts, directions, ramp): small, so the queue holds
 * many of them.
 *
 * Plans: the DDA constants of the next few segments, computed by the main loop
 * (motion_prepare_ahead) from the queued segments in order, taken by the
 * interrupt when it starts each segment. */
#ifndef QUEUE_H
#define QUEUE_H
#include <stdint.h>
#include "config.h"

enum { IT_SEG, IT_DWELL, IT_HOME, IT_SETPOS, IT_ENABLE, IT_HEATER, IT_FAN, IT_WAIT, IT_TUNE };

#define SEGF_AT_REST 0x01 /* ends at rest (ramp 255 or no deltas) */
#define SEGF_RAMP 0x02    /* ramp holds a code; else constant speed */

struct item {
    uint8_t kind;
    uint8_t flags; /* SEG: SEGF_*, dir bits in the high nibble (1 = negative); HOME: mask */
    uint8_t ramp;
    /* SEG with the step engine: the axes its schedule block carries, where the block
     * lies in the ring of chunks and the ring's head after it (step_blocks.h) */
#if STEP_ENGINE
    uint8_t blk_mask, blk_at, blk_end;
#endif
    uint32_t ticks; /* SEG, DWELL: duration in clock units */
    union {
        uint32_t n[4];  /* SEG: |delta| per axis */
        int32_t pos[4]; /* SETPOS positions, HOME targets */
        struct {
            uint8_t id, mask;
            uint16_t value;
        } cmd;
        struct {
            uint8_t id, cycles;
            uint16_t target;
        } tune; /* AUTOTUNE */
    } u;
};

extern struct item queue[QUEUE_SIZE];
extern volatile uint8_t queue_head, queue_tail;

static inline uint8_t queue_used(void)
{
    return (uint8_t)(queue_head - queue_tail);
}
static inline uint8_t queue_free(void)
{
    return (uint8_t)(QUEUE_SIZE - queue_used());
}
static inline struct item *queue_slot(uint8_t index)
{
    return &queue[index & (QUEUE_SIZE - 1)];
}

/* One axis of a prepared segment: the steps due by the end of tick i are
 * floor(N p(i / Dt) + 1/2), kept by second-order forward differences:
 * v += a; acc += v; the steps of the tick are the change of acc's top byte.
 * v and a are 48-bit fixed point with 40 fraction bits (lo: the low 16
 * fraction bits, hi: Q7.24); acc is Q8.24 modulo 256 steps and starts at 1/2.
 * The interrupt keeps no count: the last tick issues last_n corrected by the
 * difference between acc's top byte and est_low, the low byte of the count
 * the main loop estimated for the end of the tick before (the estimate and
 * the DDA differ by a step or two at most). The layout is fixed: the
 * interrupt's assembly (stepper.c) addresses the fields by offset. */
struct axis_plan {
    uint16_t v_lo;   /* 0 */
    int32_t v_hi;    /* 2 */
    uint16_t a_lo;   /* 6 */
    union {
        int32_t a_hi;      /* 8 */
        uint32_t interval; /* a steady segment's (a = 0): Q24.8 cycles between its steps
                            * for the step engine's chunk (step_recip.h) */
    };
    uint32_t acc;    /* 12 */
    uint32_t last_n; /* N minus the estimated count before the last tick */
    uint8_t est_low;
    /* cycles x 4 between steps (step_rate.h; 0: slower than fits): a steady
     * segment's from its plan, an accelerating one's from its last tick with steps */
    uint16_t period;
};

struct plan {
    uint8_t index;      /* the queue position this plan is for */
    uint8_t dir;        /* axis bit set: negative */
    uint8_t moving;     /* axis bit set: steps to make */
    uint8_t accel;      /* some a != 0 */
    uint8_t last_units; /* length of the last tick in clock units */
    uint8_t at_rest;    /* SEGF_AT_REST of the item */
    /* the step engine's axes (the others are the DDA's): a steady segment's moving axes,
     * a ramp's axes with a schedule block; blk_mask, blk_at, blk_end: the item's (the
     * high nibble of blk_mask: the axes planned with their interval only, motion.c) */
#if STEP_ENGINE
    uint8_t engine, blk_mask, blk_at, blk_end;
#define PLAN_ENGINE(p) ((p)->engine)
#else
#define PLAN_ENGINE(p) 0
#endif
    uint32_t ticks;     /* interrupt ticks (the last one last_units long) */
    float ka, kb;       /* N p(i / Dt) = N (ka i + kb i^2): positions mid-segment */
    int32_t delta[4];   /* signed steps */
    struct axis_plan ax[4];
};

extern struct plan plans[PLAN_SLOTS];
extern volatile uint8_t plan_head, plan_tail; /* main loop fills at head, interrupt takes at tail */

#endif
