/* The step timer interrupt: executes the move queue, one tick at a time. */
#ifndef STEPPER_H
#define STEPPER_H
#include <stdint.h>

struct stepper_state {
    int32_t pos[4];            /* logical step positions */
    uint32_t items_done, segments_done;
    uint32_t seg_next;         /* the number the next executed segment has (PROTOCOL.md 4,
                                  Numbering: refused and flushed segments keep theirs) */
    uint32_t motion_ticks;     /* executed durations, clock units */
    uint8_t enabled_mask, homed_mask;
    uint8_t at_rest;           /* the last executed motion ended at rest */
    uint8_t running;           /* 0: fault / estop: execute nothing */
    uint8_t current;           /* kind of the executing timed item, or 0xFF */
    uint8_t fan;
    uint16_t heater_target[2]; /* set by queued SET_HEATER items (0.1 C) */
    uint8_t heater_target_changed;
    uint8_t wait_heater;       /* WAIT item executing: heater id */
    uint16_t wait_tolerance;
};
extern volatile struct stepper_state st;

/* set by the main loop */
extern volatile uint8_t stepper_start_ok; /* the start rule allows leaving rest */
extern volatile uint8_t stepper_wait_ok;  /* the waited-for heater is within tolerance */
extern volatile uint8_t heater_duty[2], fan_duty;
/* step ticks the heater duties stay valid; the heater loop refreshes it, the
 * interrupt counts it down and zeroes the duties at 0 */
extern volatile uint16_t heater_lease;

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
/* items_done and segments_done, read with interrupts masked (the interrupt owns them). */
void stepper_counts(uint32_t *items, uint32_t *segments);
/* Ticks the executing segment or dwell has left (interrupts off). */
uint32_t stepper_ticks_left(void);

/* figures for the harness and the benchmark */
extern volatile uint16_t stepper_isr_max_cycles;
extern volatile uint16_t stepper_lost_steps;  /* pulses a tick had no room for */
extern volatile uint16_t stepper_plan_stalls; /* ticks motion waited for a plan */
extern volatile uint16_t stepper_overruns;    /* ticks computed after their start */
/* pulses issued after their tick ended, later than LATE_TOLERANCE_US */
extern volatile uint16_t stepper_late_pulses;
extern volatile uint8_t stepper_latency_max; /* cycles from a compare match to its tick's work */
/* cycles: the worst lateness of a pulse against its time on the profile (HEALTH) */
extern volatile uint16_t stepper_late_worst;
/* pulses issued more than LATE_TOLERANCE_US after their time (HEALTH late_pulses) */
extern volatile uint32_t stepper_late_tolerance;
/* Step positions now (mid-segment: the steps issued so far). */
void stepper_positions(int32_t *out);

#endif
