/* Compare B: the steps of a tick after compare A's, each at its time.
 *
 * The stepper hands compare B a tick's event list (step_wheel.h) through
 * stepper_next and arms OCR1B for the first; the interrupt issues one event each
 * time, counts it when late and arms itself for the next. */
#ifndef STEP_EVENTS_H
#define STEP_EVENTS_H

#include <stdint.h>

#include "config.h"
#include "step_wheel.h"

/* Lateness of a step: the cycles between its due time and its pulse. A step later
 * than the tolerance is counted (HEALTH late_pulses, never silent) and the worst of
 * those kept (late_worst_us, with the lateness of every step compare A issues). */
#define LATE_TOLERANCE_CYCLES (LATE_TOLERANCE_US * (F_CPU / 1000000UL))

/* compare B's next event (global: its assembly reads it) */
extern struct event *stepper_next;

#endif
