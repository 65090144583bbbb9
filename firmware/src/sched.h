/* The device clock in units of CLOCK_HZ, advanced by the step interrupt tick by tick. */
#ifndef SCHED_H
#define SCHED_H
#include <stdint.h>
#include <avr/interrupt.h>
#include "config.h"

extern volatile uint32_t sched_clock_count;

static inline uint32_t sched_clock(void)
{
    uint8_t s = SREG;
    cli();
    uint32_t t = sched_clock_count;
    SREG = s;
    return t;
}

/* The step interrupt, at the start of each tick: the tick's length in clock units. */
static inline __attribute__((always_inline)) void sched_clock_advance(uint8_t units)
{
    sched_clock_count += units;
}

/* Link time: the device clock divided by the simulation's speed-up (1 on a board),
 * for everything the host's timers meet: retransmission, announcements, the
 * start delay, the host watchdog. Updated once per main loop turn. */
extern uint32_t link_now;
void sched_update_link_time(void);

#define MS_TO_CLOCK(ms) ((uint32_t)(ms) * (CLOCK_HZ / 1000UL))
#endif
