/* How fast an axis steps: the cycles between its steps. */
#ifndef STEP_RATE_H
#define STEP_RATE_H
#include <stdint.h>

/* The cycles between the steps of an axis that moves `dist` steps (Q8.24) in `span`
 * cycles, times TIME_SCALE (4: span 2^26 / dist, to 0.4 %), the unit of the time
 * wheel (step_wheel.h); 0 when that is 2^16 or more (slower than one step per 16384
 * cycles, 977 steps/s). */
#define TIME_SCALE 4
uint16_t step_period(uint32_t dist, uint16_t span);

#endif
