/* Segments into queue items, and queue items into the step interrupt's plans. */
#ifndef MOTION_H
#define MOTION_H
#include <stdint.h>
#include "queue.h"
#include "segment.h"

/* Peak step rate check (PROTOCOL 5.1): returns the first axis over MAX_STEP_RATE and its
 * rate through *rate, else 4 when the four axes' rates summed are over a nonzero
 * TOTAL_STEP_RATE (STEP_BUDGET, 3.3) and that sum through *rate, or -1. */
int8_t motion_rate_check(const struct segment *s, uint32_t *rate);
/* Store a decoded segment in a queue item (no arithmetic beyond signs). */
void motion_store(struct item *it, const struct segment *s);
/* A segment's rate test and its item in one pass (stage_segments; two calls with their
 * own loops cost 530 cycles a segment): 0 when its step rates are over (the item's slot
 * written in part: the checked way then names the axis), else 1 with `it` stored as
 * motion_store stores it (`it` and `s` apart). */
uint8_t motion_store_checked(struct item *it, const struct segment *s);
/* Prepare the DDA constants of up to `budget` queued segments ahead of the
 * interrupt (main loop; cheap when nothing is to do). Called between the messages
 * of every long piece of work too (checking, executing a frame): with segments of
 * half a millisecond the plans last only a few milliseconds. */
void motion_prepare_some(uint8_t budget);
extern uint8_t motion_cursor; /* the next queue position to prepare */
static inline __attribute__((always_inline)) void motion_prepare_ahead(uint8_t budget)
{
    /* inline, what most calls find: every plan ready, or nothing queued to prepare */
    if ((uint8_t)(plan_head - plan_tail) < PLAN_SLOTS && motion_cursor != queue_head)
        motion_prepare_some(budget);
}
/* Forget all plans (the queue was flushed; interrupts off or the ISR idle). */
void motion_plans_reset(void);
/* Steps due by the end of tick i of an axis of n steps (float estimate). */
uint32_t motion_steps_due(float n, float ka, float kb, uint32_t i);
/* Ticks of a timed item of `units` clock units, and the length of its last tick. */
uint32_t motion_ticks_of(uint32_t units, uint8_t *last_units);

#endif
