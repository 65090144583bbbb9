/* Turning a decoded segment into the step interrupt's DDA constants. */
#ifndef MOTION_H
#define MOTION_H
#include <stdint.h>
#include "queue.h"
#include "segment.h"

/* Peak step rate check (PROTOCOL 5.1): returns the first axis over MAX_STEP_RATE
 * and its rate through *rate, or -1. */
int8_t motion_rate_check(const struct segment *s, uint32_t *rate);
/* Fill a queue item from a segment (floating point here, integers in the ISR). */
void motion_prepare(struct item *it, const struct segment *s);

#endif
