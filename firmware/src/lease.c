#include <avr/interrupt.h>
#include <avr/io.h>

#include "config.h"
#include "lease.h"
#include "pwm.h"

volatile uint16_t heater_lease_ticks;

void heater_lease_grant(const uint8_t duty[2])
{
    /* renewed before the duties change: a lease that runs out in between cannot switch
     * off the new duties, and duties above 0 never stand without a lease */
    uint8_t s = SREG;
    cli();
    heater_lease_ticks = HEATER_LEASE_TICKS;
    SREG = s;
    pwm_set_heater(0, duty[0]);
    pwm_set_heater(1, duty[1]);
}

void heater_lease_end(void)
{
    uint8_t s = SREG;
    cli();
    heater_lease_ticks = 0;
    SREG = s;
}

void __attribute__((noinline)) heater_lease_expired(void)
{
    pwm_heaters_off();
}
