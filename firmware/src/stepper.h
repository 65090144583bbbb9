/* The move queue's execution, one step tick at a time (the tick's interrupt runs it). */
#ifndef STEPPER_H
#define STEPPER_H
#include <stdint.h>

#include "config.h"

/* What the interrupt has executed, one consistent snapshot (stepper_progress). */
struct stepper_progress {
    uint32_t items_done, segments_done;
    uint32_t motion_ticks;     /* executed durations, clock units */
    uint32_t ticks_left;       /* ticks the executing segment or dwell has left */
    uint8_t current;           /* kind of the executing timed item (IT_*), or 0xFF */
    uint8_t tail;              /* the queue's tail (its executing or next item) then */
    uint8_t enabled_mask, homed_mask;
};
/* The one way the main loop reads the interrupt's progress: without masking it. */
void stepper_progress(struct stepper_progress *out);
/* Changes whenever what a reset keeps (items_done, segments_done, enabled_mask) may
 * have changed: the tick interrupt's count with the main loop's own writes. Read it
 * before stepper_progress: an unchanged mark means an unchanged progress. */
uint16_t stepper_change_mark(void);
/* Parts of it, for callers that keep a small stack frame (the shutdown path's). */
void stepper_counts(uint32_t *items, uint32_t *segments);
uint8_t stepper_homed_mask(void);

/* set by the main loop */
#if STEP_ENGINE
/* The queue position (queue_tail) of the segment the start rule lets leave rest. A verdict
 * holds only for the queue it was taken on: one taken while the block before was still
 * executing (that block's end counted as queued) started the next block as soon as the
 * first ended at rest, with two of its pieces queued. */
extern volatile uint8_t stepper_start_for;
#else
extern volatile uint8_t stepper_start_ok; /* the start rule allows leaving rest */
#endif
extern volatile uint8_t stepper_wait_ok;  /* the waited-for heater is within tolerance */

/* SET_HEATER items the interrupt executed since the last call: a mask of the heaters
 * whose target changed, and their targets (0.1 C) in targets[]. */
uint8_t stepper_take_heater_targets(uint16_t targets[2]);
/* Forget the targets executed but not taken yet (the shutdown path). */
void stepper_drop_heater_targets(void);
/* The executing WAIT item: WAIT_NONE, or its heater and tolerance (0.1 C), and whether
 * a SET_HEATER executed before it is still on its way to the heater (then it is not
 * decided on the old target). Call with interrupts masked to act on the answer. */
enum { WAIT_NONE, WAIT_HEATER, WAIT_TARGET_PENDING };
uint8_t stepper_waiting_for(uint8_t *heater, uint16_t *tolerance);

/* raised by the interrupt, taken by the main loop */
struct stepper_report {
    uint8_t error, axis;       /* ERR_* or 0 */
    uint32_t item, segment;
    int32_t value;
    uint8_t homed;             /* a HOME item completed */
    uint32_t homed_item;
};
extern volatile struct stepper_report stepper_report;

/* Pins and Timer1; the motors in hold_mask stay enabled (after a watchdog reset). */
void stepper_init(uint8_t hold_mask);
/* Stop now (fault, estop): the executing item is abandoned, nothing more runs. */
void stepper_halt(void);
void stepper_resume(void);
/* Empty the queue: its items count as done; the next segment queued is number
 * segments_received + 1. */
void stepper_flush(uint32_t items_received, uint32_t segments_received);
void stepper_disable_all(void);
uint8_t stepper_moving(void);

/* figures for the harness and the benchmark (the tick's timing has its own,
 * step_timer.h) */
extern volatile uint16_t stepper_lost_steps;  /* pulses a tick had no room for */
extern volatile uint16_t stepper_plan_stalls; /* ticks motion waited for a plan */
/* Step positions now (mid-segment: the steps issued so far). */
void stepper_positions(int32_t *out);

/* What the tick interrupt (step_tick_isr.c) asks of the execution each tick. */
/* At a tick's start, with interrupts on: the markers, the scheduler's clock, the lease. */
void stepper_tick_chores(void);
/* The next tick, into next_tick (interrupts on, compare A masked). */
void stepper_compute(void);

#endif
