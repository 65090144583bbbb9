/* The step tick's interrupt, Timer1's compare A: it starts the tick (step_timer.c: its
 * directions and the steps due at once, compare B armed for the rest), has the queue's
 * execution (stepper.c) do the tick's chores and compute the next tick, and ends the
 * tick (step_timer.c: its figures, a step handed over to this tick's compare B).
 *
 * The computation runs with interrupts on, so compare B keeps its phases'
 * time. Should it overrun into the next tick, that tick's interrupt only
 * notes it and this one starts the tick at once (late), as silicon would
 * (without masking compare A: simavr 1.6 never queues an interrupt that was
 * enabled after its flag rose). Nothing lives across the calls, so the entry
 * saves only what a call clobbers. */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "config.h"
#include "step_pins.h"
#include "step_tick.h"
#include "step_timer.h"
#include "stepper.h"

static volatile uint8_t computing; /* the tick's computation runs (interrupts on) */

/* Compare A's entry, before the compiler's prologue (about 50 cycles): a compare B
 * event still pending at the boundary (another interrupt held compare B past it, and
 * compare A comes first) has its pulses raised at once (stepper_next, step_events.h);
 * tick_start's flush ends them. Then the tick proper, a signal handler entered as if
 * from the vector. */
#if STEP_ENGINE
/* interrupts on from its first instruction: the steppers' edges do not wait for its
 * prologue (compare A cannot come again before the tick's end) */
void __vector_tick(void) __attribute__((interrupt, used));
#else
void __vector_tick(void) __attribute__((signal, used));
#endif
ISR(TIMER1_COMPA_vect, ISR_NAKED)
{
    __asm__ volatile(
        "push r24\n\t"
        "in r24, __SREG__\n\t"
        "push r24\n\t"
        "lds r24, %[timsk]\n\t"
        "sbrs r24, %[ocieb]\n\t"
        "rjmp 1f\n\t"
        "lds r24, computing\n\t"
        "tst r24\n\t"
        "brne 1f\n\t" /* an overrun: the interrupted tick flushes */
        "push r30\n\t"
        "push r31\n\t"
        "lds r30, stepper_next\n\t"
        "lds r31, stepper_next+1\n\t"
        "ld r24, Z\n\t"
        "sts prepulsed, r24\n\t"
        STEP_PULSE_ASM("2")
        "pop r31\n\t"
        "pop r30\n"
        "1:\n\t"
        "pop r24\n\t"
        "out __SREG__, r24\n\t"
        "pop r24\n\t"
        "jmp __vector_tick\n\t"
        :
        : STEP_PULSE_ASM_OPERANDS, [timsk] "n"(_SFR_MEM_ADDR(TIMSK1)), [ocieb] "I"(OCIE1B));
}

void __vector_tick(void)
{
    tick_gen++;
    if (computing) {
        tick_missed = 1;
        return;
    }
    do {
        if (STEP_ENGINE && quiet_start()) {
            /* nothing at this tick's start is due at an exact time (the steps are the
             * step engine's): the steppers' interrupts may come first */
            computing = 1;
            sei();
            tick_start();
        } else {
            cli();
            tick_start();
            computing = 1;
            sei();
        }
        stepper_tick_chores();
        stepper_compute();
        tail_guard();
        if (STEP_ENGINE)
            motion_marker(); /* computing: a compare A now only notes itself */
        cli();
        computing = 0;
        if (!STEP_ENGINE)
            motion_marker();
    } while (tick_end());
    hand_over_first();
    if (STEP_ENGINE)
        sei(); /* the epilogue (about 40 cycles of pops) need not hold the steppers' edges:
                * the next tick is not due before it ends */
}
