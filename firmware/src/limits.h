/* The limit switches at the end of each module's travel (RAMPS MAX sockets): a switch
 * pressed on two step ticks in a row (debounced) while its module moves toward it stops
 * the motion (ENDSTOP_HIT). Checked by the step interrupt every tick of a segment. */
#ifndef LIMITS_H
#define LIMITS_H
#include <stdint.h>

#include "step_pins.h"

/* the modules whose switch was pressed on the last tick while moving toward it */
extern uint8_t limits_seen;

/* Whether this tick needs limits_check: a switch pressed now or on the last tick (a
 * few cycles: the switches are read directly). */
static inline __attribute__((always_inline)) uint8_t limits_active(void)
{
    return limits_pressed() | limits_seen;
}

/* The module (0..2) stopped by its limit switch this tick, or -1: of a segment moving
 * the modules of `moving`, toward negative those of `negative`. */
int8_t limits_check(uint8_t moving, uint8_t negative);

#endif
