/* The compares simavr 1.6 drops just after a 16-bit timer's overflow, served as the
 * chip serves them (overflow_compares.c). */
#ifndef OVERFLOW_COMPARES_H
#define OVERFLOW_COMPARES_H
#include <sim_avr.h>

/* Find the step engine's Timer3 and Timer5 (once, after the AVR is made). */
void overflow_compares_init(avr_t *avr);

/* Follow their overflows while they count in normal mode: call it often (the harness's
 * poll); a reset, which drops every cycle timer, or a timer started again is taken up
 * at the next call. */
void overflow_compares_poll(avr_t *avr);

/* compares with their interrupt enabled that simavr had dropped, served here (the
 * harness's stats) */
extern unsigned overflow_compares_served;

#endif
