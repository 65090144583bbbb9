/* HOME: the modules of a HOME item step toward their homing switches at
 * DEV_HOMING_RATE, one step every HOME_TICKS homing ticks (HOME_TICK_UNITS long), until
 * every switch closes; a module whose switch is pressed at the start first steps away
 * until it releases. Homing from d steps takes d / DEV_HOMING_RATE seconds exactly, as
 * in the Python model. Run by the step interrupt (stepper.c). */
#ifndef HOMING_H
#define HOMING_H
#include <stdint.h>

/* Begin homing the modules of mask (bits 0..2). */
void homing_start(uint8_t mask);

enum { HOMING_WAIT, HOMING_STEP, HOMING_DONE, HOMING_FAILED };
/* One homing tick: HOMING_STEP with the modules that step now in *stepping (those of
 * them moving away from their switch in *backing off), HOMING_WAIT between steps,
 * HOMING_DONE once every switch closed, HOMING_FAILED after DEV_HOMING_MAX_STEPS. */
uint8_t homing_tick(uint8_t *stepping, uint8_t *backing);
/* the steps taken so far (HOMING_FAILED's figure) */
uint32_t homing_steps(void);

#endif
