/* What the step tick's timing (step_timer.c) and the queue's execution (stepper.c)
 * share: the two ticks in flight and the directions, the interrupt's count, and what
 * the interrupt asks of the execution each tick. */
#ifndef STEP_TICK_H
#define STEP_TICK_H
#include <stdint.h>

#include "step_wheel.h"

extern struct out *this_tick; /* the tick being issued */
extern struct out *next_tick; /* the tick being computed */
extern uint8_t cur_dir;       /* the direction pins now (axis bit set: negative) */
/* bumped by every tick interrupt: the main loop's snapshots retry until none came
 * between their first and last read, instead of masking interrupts */
extern volatile uint8_t tick_gen;

/* Timer1 running, its compare A interrupt enabled. */
void step_timer_init(void);
/* At a tick's start, with interrupts on: the markers, the scheduler's clock, the lease. */
void stepper_tick_chores(void);
/* The next tick, into next_tick (interrupts on, compare A masked). */
void stepper_compute(void);

#endif
