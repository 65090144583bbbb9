#include "config.h"
#include "homing.h"
#include "protocol_gen.h"
#include "step_pins.h"

#define HOME_TICKS (CLOCK_HZ / ((uint32_t)DEV_HOMING_RATE * HOME_TICK_UNITS))
_Static_assert(HOME_TICKS * DEV_HOMING_RATE * HOME_TICK_UNITS == CLOCK_HZ,
               "a homing step must take a whole number of homing ticks");

static uint8_t homing_mask;    /* modules whose switch has not closed yet */
static uint8_t backing_mask;   /* modules stepping away from a switch pressed at the start */
static uint8_t ticks_to_step;  /* homing ticks until the next step */
static uint32_t steps_taken;

void homing_start(uint8_t mask)
{
    homing_mask = mask;
    backing_mask = endstops() & mask;
    ticks_to_step = 0;
    steps_taken = 0;
}

uint32_t homing_steps(void)
{
    return steps_taken;
}

uint8_t __attribute__((noinline)) homing_tick(uint8_t *stepping_out, uint8_t *backing_out)
{
    if (ticks_to_step) {
        ticks_to_step--;
        return HOMING_WAIT;
    }
    ticks_to_step = HOME_TICKS - 1;
    uint8_t stepping = 0, backing = 0, pressed = endstops();
    for (uint8_t k = 0; k < 3; k++) {
        uint8_t bit = (uint8_t)(1 << k);
        if (!(homing_mask & bit))
            continue;
        uint8_t hit = pressed & bit;
        if (backing_mask & bit) {
            if (hit) {
                stepping |= bit;
                backing |= bit;
                continue;
            }
            backing_mask &= (uint8_t)~bit; /* released: approach again */
        }
        if (hit)
            homing_mask &= (uint8_t)~bit;
        else
            stepping |= bit;
    }
    if (!homing_mask)
        return HOMING_DONE;
    if (++steps_taken > (uint32_t)DEV_HOMING_MAX_STEPS)
        return HOMING_FAILED;
    *stepping_out = stepping;
    *backing_out = backing;
    return HOMING_STEP;
}
