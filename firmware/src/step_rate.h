/* How fast an axis steps: the cycles between its steps. */
#ifndef STEP_RATE_H
#define STEP_RATE_H
#include <stdint.h>

/* Cycles x 8 between the steps of an axis that moves `dist` steps (Q8.24) in `span`
 * cycles (span 2^27 / dist, to 0.4 %); 0 when that is 2^16 or more (slower than one
 * step per 8192 cycles). */
uint16_t step_cycles8(uint32_t dist, uint16_t span);

#endif
