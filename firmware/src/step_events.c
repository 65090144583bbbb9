/* Compare B's interrupt (step_events.h), in hand-written assembly. */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "board_ramps14.h"
#include "config.h"
#include "step_events.h"
#include "step_pins.h"

struct event *stepper_next;


/* The event's pulses ended (step_pins.h, pulse_off): all four pins without the step
 * engine; with it, the event's own (its mask, 3 bytes before Z: 10 cycles more) */
#if STEP_ENGINE
#define LOWER_PULSES                                                                       \
    "sbiw r30, 3\n\t"                                                                      \
    "ld r24, Z\n\t"                                                                        \
    "sbrc r24, 0\n\t"                                                                      \
    "cbi %[pf], %[xb]\n\t"                                                                 \
    "sbrc r24, 1\n\t"                                                                      \
    "cbi %[pf], %[yb]\n\t"                                                                 \
    "sbrc r24, 3\n\t"                                                                      \
    "cbi %[pa], %[eb]\n\t"                                                                 \
    "sbrs r24, 2\n\t"                                                                      \
    "rjmp 6f\n\t"                                                                          \
    "lds r24, %[pl]\n\t"                                                                   \
    "andi r24, %[nzm]\n\t"                                                                 \
    "sts %[pl], r24\n"                                                                      \
    "6:\n\t"
#else
#define LOWER_PULSES                                                                       \
    "cbi %[pf], %[xb]\n\t"                                                                 \
    "cbi %[pf], %[yb]\n\t"                                                                 \
    "cbi %[pa], %[eb]\n\t"                                                                 \
    "lds r24, %[pl]\n\t"                                                                   \
    "andi r24, %[nzm]\n\t"                                                                 \
    "sts %[pl], r24\n\t"
#endif

/* Compare B: a tick's events after the first, one per interrupt, 50-odd cycles
 * (hand-written: the compiler's version took twice that). Raises the event's pulses,
 * counts it if late, arms OCR1B for the next (or just ahead of now, if that is
 * already past) or disables itself after the last, then ends the pulses >= 2 us
 * after they rose. */
ISR(TIMER1_COMPB_vect, ISR_NAKED)
{
    __asm__ volatile(
        "push r24\n\t"
        "in r24, __SREG__\n\t"
        "push r24\n\t"
        "push r30\n\t"
        "push r31\n\t"
        "lds r30, stepper_next\n\t"
        "lds r31, stepper_next+1\n\t"
        "ld r24, Z+\n\t" /* this event's axes */
        STEP_PULSE_ASM("1")
        "push r25\n\t"
        "push r26\n\t"
        "push r27\n\t"
        /* lateness: TCNT1 - at, late beyond the tolerance: counted */
        "lds r26, %[tcntl]\n\t"
        "lds r27, %[tcntl]+1\n\t"
        "ld r24, Z+\n\t"
        "ld r25, Z+\n\t"
        "sub r26, r24\n\t"
        "sbc r27, r25\n\t"
        "cpi r26, lo8(%[tol] + 1)\n\t"
        "ldi r24, hi8(%[tol] + 1)\n\t"
        "cpc r27, r24\n\t"
        "brlt 2f\n\t" /* within the tolerance, or early (merged with an earlier step) */
        "call stepper_late_step\n"
        "2:\n\t"
        /* the next event: a mask of 0 ends the list */
        "ld r24, Z\n\t"
        "tst r24\n\t"
        "brne 3f\n\t"
        "lds r24, %[timsk]\n\t"
        "andi r24, %[nocieb]\n\t"
        "sts %[timsk], r24\n\t"
        "rjmp 5f\n"
        "3:\n\t"
        "ldd r24, Z+1\n\t"
        "ldd r25, Z+2\n\t"
        "lds r26, %[tcntl]\n\t"
        "lds r27, %[tcntl]+1\n\t"
        "adiw r26, 24\n\t"
        "cp r26, r24\n\t"
        "cpc r27, r25\n\t"
        "brlo 4f\n\t"
        "movw r24, r26\n\t" /* already past: just ahead of now */
        "adiw r24, 16\n"
        "4:\n\t"
        "sts %[ocrl]+1, r25\n\t"
        "sts %[ocrl], r24\n"
        "5:\n\t"
        "sts stepper_next+1, r31\n\t"
        "sts stepper_next, r30\n\t"
        "pop r27\n\t"
        "pop r26\n\t"
        "pop r25\n\t"
        LOWER_PULSES /* high since the sbi: >= 34 cycles on every path */
        "pop r31\n\t"
        "pop r30\n\t"
        "pop r24\n\t"
        "out __SREG__, r24\n\t"
        "pop r24\n\t"
        "reti\n\t"
        :
        : STEP_PULSE_ASM_OPERANDS,
          [nzm] "n"(0xFF & ~_BV(Z_STEP_BIT)), [timsk] "n"(_SFR_MEM_ADDR(TIMSK1)),
          [nocieb] "n"(0xFF & ~_BV(OCIE1B)), [ocrl] "n"(_SFR_MEM_ADDR(OCR1BL)),
          [tcntl] "n"(_SFR_MEM_ADDR(TCNT1L)), [tol] "n"(LATE_TOLERANCE_CYCLES));
}
/* compare B's assembly assumes the RAMPS step ports: X and Y on PORTF, Z on PORTL, E on PORTA */
_Static_assert(sizeof(struct event) == 3 && LATE_TOLERANCE_CYCLES < 0x7FFF, "compare B's layout");

/* A step compare B issued late beyond the tolerance, r27:r26 cycles: counted, the
 * worst kept. Called from compare B's assembly, which saved r24..r27, r30, r31 and
 * SREG: this saves whatever else it uses. */
void stepper_late_step(void) __attribute__((naked, used));
void stepper_late_step(void)
{
    __asm__ volatile(
        "lds r24, stepper_late_tolerance\n\t"
        "lds r25, stepper_late_tolerance+1\n\t"
        "adiw r24, 1\n\t"
        "sts stepper_late_tolerance+1, r25\n\t"
        "sts stepper_late_tolerance, r24\n\t"
        "brne 1f\n\t"
        "lds r24, stepper_late_tolerance+2\n\t"
        "lds r25, stepper_late_tolerance+3\n\t"
        "adiw r24, 1\n\t"
        "sts stepper_late_tolerance+3, r25\n\t"
        "sts stepper_late_tolerance+2, r24\n"
        "1:\n\t"
        "lds r24, stepper_late_worst\n\t"
        "lds r25, stepper_late_worst+1\n\t"
        "cp r24, r26\n\t"
        "cpc r25, r27\n\t"
        "brsh 2f\n\t"
        "sts stepper_late_worst+1, r27\n\t"
        "sts stepper_late_worst, r26\n"
        "2:\n\t"
        "ret\n\t");
}
