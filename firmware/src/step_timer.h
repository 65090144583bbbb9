/* The step tick's timing (step_timer.c): Timer1, the start and end of each tick, its
 * figures; the parts of a tick that its interrupt (step_tick_isr.c) runs around the
 * queue's execution. */
#ifndef STEP_TIMER_H
#define STEP_TIMER_H
#include <avr/io.h>
#include <stdint.h>

#include "step_tick.h"

/* Timer1 running, its compare A interrupt enabled. */
void step_timer_init(void);

/* The parts of a tick, in the interrupt's order (step_timer.c says more); tick_start,
 * tick_end and hand_over_first with interrupts off. */
void tick_start(void);      /* its directions, the steps due at once, compare B armed */
void motion_marker(void);   /* the simulator's marker of motion starting or stopping */
uint8_t tick_end(void);     /* its figures; 1: the next tick has begun already */
void hand_over_first(void); /* the next tick's first step to this tick's compare B */
/* set when a tick's start came while the one before was still computing (or its
 * shorter period had passed already); tick_end counts it */
extern volatile uint8_t tick_missed;
/* the axes of a pending compare B event that compare A's entry raised (its assembly
 * sets it, tick_start's flush ends their pulses) */
extern volatile uint8_t prepulsed;

/* The tick's tail runs with interrupts off (~130 cycles to its return): a compare B
 * event due in that time goes out first, unless it is so close to the tick's end
 * that waiting for it would run the tail into the next tick. */
#define TAIL_CYCLES 144
static inline void tail_guard(void)
{
    uint16_t last = (uint16_t)(OCR1A - TAIL_CYCLES);
    while (TIMSK1 & _BV(OCIE1B)) {
        uint16_t b = OCR1B;
        if ((uint16_t)(b - TCNT1) >= TAIL_CYCLES || b > last)
            break;
    }
}

/* The tick that starts now issues no step and keeps the directions, and no step of the
 * tick that ends is pending (tick_start then touches no pin). */
static inline __attribute__((always_inline)) uint8_t quiet_start(void)
{
    return !next_tick->ev[0].mask && !((next_tick->dir ^ cur_dir) & next_tick->own) &&
           !(TIMSK1 & _BV(OCIE1B));
}

/* figures for the harness and the benchmark */
extern volatile uint16_t stepper_isr_max_cycles;
extern volatile uint16_t stepper_overruns; /* ticks computed after their start */
/* pulses issued after their tick ended, later than LATE_TOLERANCE_US */
extern volatile uint16_t stepper_late_pulses;
extern volatile uint8_t stepper_latency_max; /* cycles from a compare match to its tick's work */
/* cycles: the worst lateness of a pulse against its time on the profile (HEALTH) */
extern volatile uint16_t stepper_late_worst;
/* pulses issued more than LATE_TOLERANCE_US after their time (HEALTH late_pulses) */
extern volatile uint32_t stepper_late_tolerance;

#endif
