/* The device's table of reciprocals (firmware_protocol/step_schedule.py
 * reciprocal_table): q[n] = round(UNIT_CYCLES 2^24 / n) for n = 1..PREDICT_MAX_STEPS, so
 * a constant-speed axis of |n| steps over D clock units steps every
 * I = (D q[|n|] + 2^15) >> 16 cycles (Q24.8), without a division. The host computes the
 * same integers and checks the edges they give. */
#ifndef STEP_RECIP_H
#define STEP_RECIP_H
#include <avr/pgmspace.h>
#include <stdint.h>

#define PREDICT_MAX_STEPS 1024
#define PREDICT_MAX_TICKS 0xFFFFUL
extern const uint32_t step_recip[PREDICT_MAX_STEPS + 1] PROGMEM;

/* The interval (Q24.8 cycles) of |n| >= 1 steps evenly over D clock units: the table's
 * where the host predicts it, else by division (exact to the rounding). */
uint32_t step_interval(uint32_t n, uint32_t ticks);

#endif
