/* The heater lease: the control loop's heater duties stand for HEATER_LEASE_TICKS step
 * ticks. The control loop renews the lease with the duties it sets every control
 * period; the step tick counts it down and, should the control loop stop (a main loop
 * stuck in a long piece of work, a fault in it), switches the heaters off itself when
 * the lease runs out. */
#ifndef LEASE_H
#define LEASE_H
#include <stdint.h>

/* step ticks the duties have left; 0: no lease (the heaters are off) */
extern volatile uint16_t heater_lease_ticks;

/* The control loop's duties (hotend, bed), with the lease renewed first. */
void heater_lease_grant(const uint8_t duty[2]);
/* No lease (the shutdown path: the heaters are switched off there). */
void heater_lease_end(void);
/* The lease ran out: the heaters off (the step tick's). */
void heater_lease_expired(void);

/* One step tick of the lease (the step interrupt; about ten cycles). */
static inline __attribute__((always_inline)) void heater_lease_tick(void)
{
    uint16_t left = heater_lease_ticks;
    if (left) {
        heater_lease_ticks = --left;
        if (!left)
            heater_lease_expired();
    }
}

#endif
