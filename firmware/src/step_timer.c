/* The step tick's timing: Timer1 in CTC mode, one compare match per tick.
 *
 * OCR1A is rewritten at the start of a tick whose length differs from the last one's
 * (a segment's or dwell's last tick). Work is pipelined one tick deep: at a tick's
 * start the interrupt sets the tick's directions and issues the steps due at once, all
 * computed during the previous interrupt, and arms compare B (step_events.c) for the
 * rest of the tick's events; then, with its own interrupt masked and the others allowed
 * (so compare B keeps its time), stepper.c computes the next tick (the interrupt itself,
 * which runs these parts in their order, is step_tick_isr.c). It notes the ticks that
 * overran their boundary (their steps keep their times) and hands a step due at the
 * next tick's very start to this tick's compare B.
 *
 * Pulses are high for at least 2 us and a direction change leads the next pulse by at
 * least 1 us (A4988: 1 us / 200 ns, DRV8825: 1.9 us / 650 ns, TMC2208: 0.1 us /
 * 20 ns). A pulse issued later than LATE_TOLERANCE_US after its time is counted
 * (HEALTH late_pulses) and the worst lateness kept. */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "board_ramps14.h"
#include "config.h"
#include "sim_hooks.h"
#include "sim_markers.h"
#include "step_engine.h"
#include "step_events.h"
#include "step_pins.h"
#include "step_timer.h"
#include "step_wheel.h"

volatile uint16_t stepper_isr_max_cycles;
volatile uint16_t stepper_overruns, stepper_late_pulses;
volatile uint8_t stepper_latency_max;
volatile uint16_t stepper_late_worst;
volatile uint32_t stepper_late_tolerance;
volatile uint8_t tick_missed;
static uint8_t handed_over; /* the next tick's first event went out with this one's */
volatile uint8_t prepulsed;
static uint8_t ocr_units = TICK_UNITS; /* the length of the tick in progress */

void step_timer_init(void)
{
    this_tick->units = next_tick->units = TICK_UNITS;
    this_tick->own = next_tick->own = STEP_ENGINE ? 0 : 0x0F;
    /* Timer1: CTC on OCR1A, no prescaler; in the simulator build compare C toggles OC1C
     * (MARK_EDGE) when OCR1C is set to match one cycle into the next tick */
    TCCR1A = SIM_HOOKS ? _BV(COM1C0) : 0;
    TCCR1B = 0;
    TCNT1 = 0;
    OCR1A = TICK_CYCLES - 1;
    OCR1C = EDGE_NEVER;
    if (STEP_ENGINE)
        step_engine_start_timers(_BV(WGM12) | _BV(CS10));
    else
        TCCR1B = _BV(WGM12) | _BV(CS10);
    TIMSK1 = _BV(OCIE1A);
}

static uint16_t late_cycles; /* cycles of earlier ticks handled in this interrupt */

/* One step event now, from compare A (with interrupts off): its lateness noted as
 * compare B notes it, pulses 2 us high. */
static void __attribute__((noinline)) event_now(uint8_t m, uint16_t at, uint16_t now)
{
    pulse_on(m);
    uint16_t l = (int16_t)(now - at) > 0 ? (uint16_t)(now - at) : 0;
    if (l > stepper_late_worst)
        stepper_late_worst = l;
    if (l > LATE_TOLERANCE_CYCLES)
        stepper_late_tolerance++;
    __builtin_avr_delay_cycles(PULSE_CYCLES - 8);
    pulse_off(m);
}

/* Events of the tick that just ended that compare B has not issued yet (the tick
 * started so late that its events ran past its end): issued now, before the new
 * tick's, 2 us high and 2 us low each, so no step is lost; each is counted late.
 * With interrupts off. */
static void __attribute__((noinline)) flush_events(void)
{
    /* lateness: from the event's time in the tick that ended (its period) to now */
    uint16_t ended = (uint16_t)(ocr_units * UNIT_CYCLES);
    const struct event *e = stepper_next;
    if (prepulsed) {
        /* raised by compare A's entry: held high, then ended */
        uint16_t l = (uint16_t)(TCNT1 + ended - e->at);
        if (l > stepper_late_worst)
            stepper_late_worst = l;
        if (l > LATE_TOLERANCE_CYCLES) {
            stepper_late_pulses++;
            stepper_late_tolerance++;
        }
        uint8_t m = prepulsed; /* (the axes it raised) */
        prepulsed = 0;
        __builtin_avr_delay_cycles(PULSE_CYCLES);
        pulse_off(m);
        __builtin_avr_delay_cycles(PULSE_CYCLES);
        e++;
    }
    for (; e->mask; e++) {
        uint16_t l = (uint16_t)(TCNT1 + ended - e->at);
        pulse_on(e->mask);
        if (l > stepper_late_worst)
            stepper_late_worst = l;
        if (l > LATE_TOLERANCE_CYCLES) {
            stepper_late_pulses++;
            stepper_late_tolerance++;
        }
        __builtin_avr_delay_cycles(PULSE_CYCLES);
        pulse_off(e->mask);
        __builtin_avr_delay_cycles(PULSE_CYCLES);
    }
    TIMSK1 &= (uint8_t)~_BV(OCIE1B);
    TIFR1 = _BV(OCF1B);
}

/* Events due within this many cycles are issued by compare A itself (it holds the
 * CPU until then); compare B is armed for the first one after. */
#define A_EARLY 48

/* The start of a tick, with interrupts off and as short as it can be: this tick's
 * length, directions, the events due at once, compare B armed for the rest. */
void __attribute__((noinline)) tick_start(void)
{
    uint8_t entry = TCNT1L; /* cycles since the compare match (< 256 unless late) */
    if (TIMSK1 & _BV(OCIE1B))
        flush_events(); /* compare B disables itself after a tick's last event */
    struct out *e = next_tick;
    next_tick = this_tick;
    this_tick = e;
#if STEP_ENGINE
    step_clock_this_tick = step_clock_next_tick;
    step_clock_next_tick += (uint32_t)(uint16_t)(e->units * UNIT_CYCLES) << STEP_FRAC_BITS;
#endif
    struct event *ev = e->ev;
    if (handed_over) {
        ev++; /* issued by the last tick's compare B, just before this tick began */
        handed_over = 0;
    }
    /* (masked: the step engine's interrupts set their own axes' bits of cur_dir) */
    uint8_t sreg = SREG;
    cli();
    uint8_t dir = (uint8_t)((e->dir & e->own) | (cur_dir & (uint8_t)~e->own));
    if (dir != cur_dir) {
        /* first, and in a tick without steps too: a reversal's first step, at the next
         * tick's start, can then go out with this tick's compare B (hand_over_first) */
        apply_dirs(dir);
        cur_dir = dir;
        __builtin_avr_delay_cycles(16);
    }
    SREG = sreg;
    uint16_t high_from = 0;
    uint8_t first = 0;
    if (ev->mask && !late_cycles) {
        /* a first step due at once goes out before anything else (the bookkeeping
         * below runs while its pulse is high) */
        uint16_t at = ev->at;
        if ((int16_t)(at - TCNT1) < A_EARLY) {
            while ((int16_t)(TCNT1 - at) < 0)
                ;
            pulse_on(ev->mask);
            high_from = TCNT1;
            uint16_t l = (int16_t)(high_from - at) > 0 ? (uint16_t)(high_from - at) : 0;
            if (l > stepper_late_worst)
                stepper_late_worst = l;
            if (l > LATE_TOLERANCE_CYCLES)
                stepper_late_tolerance++;
            first = ev->mask; /* (not 0) */
            ev++;
        }
    }
    uint8_t units = e->units;
    if (units != ocr_units) {
        ocr_units = units;
        uint16_t top = (uint16_t)(units * UNIT_CYCLES - 1);
        OCR1A = top;
        uint16_t now = TCNT1;
        if ((uint16_t)(now + 8) > top) {
            /* this (shorter) tick is over already: its compare match would be missed
             * and the timer run on to 0xFFFF (a 4 ms hole). Wrap the period by hand,
             * keeping the time base, and start the next tick at once (late). */
            TCNT1 = (uint16_t)(now - top + 1);
            tick_missed = 1;
        }
    }
    if (entry > stepper_latency_max && !late_cycles)
        stepper_latency_max = entry;
    if (first) {
        while ((uint16_t)(TCNT1 - high_from) < PULSE_CYCLES)
            ;
        pulse_off(first);
        __builtin_avr_delay_cycles(PULSE_CYCLES); /* low before another pulse */
    }
    if (!ev->mask)
        return;
    for (; ev->mask; ev++) {
        /* (a tick started late runs in its own timer period all the same: its later
         * steps keep their time) */
        uint16_t at = ev->at, now = TCNT1;
        if ((int16_t)(at - now) <= 0) {
            event_now(ev->mask, at, now);
        } else if (at - now < A_EARLY) {
            while ((int16_t)(TCNT1 - at) < 0)
                ;
            event_now(ev->mask, at, at);
        } else {
            break;
        }
        __builtin_avr_delay_cycles(PULSE_CYCLES); /* low before another pulse */
    }
    stepper_next = ev;
    if (ev->mask) {
        OCR1B = ev->at;
        TIFR1 = _BV(OCF1B); /* a match earlier in this tick left its flag */
        TIMSK1 |= _BV(OCIE1B);
    }
}

/* Motion starts or stops at the next tick boundary: MARK_EDGE toggles there
 * (armed just after the next tick's computation, before that boundary). */
void __attribute__((noinline)) motion_marker(void)
{
    markers_motion_change(this_tick, next_tick);
}

/* After a tick's computation: the interrupt's length so far, and whether the
 * next tick has already begun (returns 1: start it now). */
uint8_t __attribute__((noinline)) tick_end(void)
{
    uint16_t used = TCNT1 + late_cycles;
    if (tick_missed) {
        tick_missed = 0;
        stepper_overruns++;
        used += (uint16_t)(ocr_units * UNIT_CYCLES);
        late_cycles += (uint16_t)(ocr_units * UNIT_CYCLES);
    } else {
        late_cycles = 0;
    }
    if (used > stepper_isr_max_cycles)
        stepper_isr_max_cycles = used;
    return late_cycles != 0;
}

/* A step due in the first cycles of the next tick goes out from this tick's compare
 * B, HANDOVER_LEAD cycles before the boundary (its pulse rises about when the tick
 * begins), rather than from compare A once its entry has run (~130 cycles, 8 us,
 * late). Only when the next tick keeps the directions and this one ends on time. */
#define HANDOVER_LEAD 8
void __attribute__((noinline)) hand_over_first(void)
{
    const struct event *f = next_tick->ev;
    uint8_t n = this_tick->n;
    if (!f->mask || f->at >= A_EARLY || ((next_tick->dir ^ cur_dir) & next_tick->own) ||
        n >= EV_MAX)
        return;
    uint16_t at = (uint16_t)(ocr_units * UNIT_CYCLES - 1 - HANDOVER_LEAD);
    if ((int16_t)(at - TCNT1) < 24)
        return; /* too close to arm compare B in time */
    struct event *e = &this_tick->ev[n];
    e->mask = f->mask;
    e->at = at;
    e[1].mask = 0;
    this_tick->n = (uint8_t)(n + 1);
    handed_over = 1;
    if (!(TIMSK1 & _BV(OCIE1B))) {
        stepper_next = e;
        OCR1B = at;
        TIFR1 = _BV(OCF1B);
        TIMSK1 |= _BV(OCIE1B);
    }
}
