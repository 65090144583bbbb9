/* What the step tick's parts share: the two ticks in flight and the directions, the
 * interrupt's count. The tick's timing (step_timer.c) issues this_tick and swaps the
 * two, the queue's execution (stepper.c) computes next_tick, the step engine sets its
 * own axes' bits of cur_dir; the interrupt (step_tick_isr.c) runs them each tick. */
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

#endif
