/* The time wheel: where inside a tick each step goes.
 *
 * The stepper's DDA says how many steps an axis makes in a tick and how far past its
 * last step boundary it starts; the wheel turns that into times. Each step lands in
 * a slot of SLOT_CYCLES at the time the segment's profile gives it; wheel_take turns
 * the occupied slots into the tick's event list (the axes pulsed together and when),
 * which compare B issues. Placing a step costs a multiply-free add per step (the
 * axis's cycles per step come from step_rate.c), so this is inline where it is hot. */
#ifndef STEP_WHEEL_H
#define STEP_WHEEL_H

#include <stdint.h>

#include "config.h"
#include "mul16.h"
#include "step_rate.h" /* TIME_SCALE */

#define PULSE_CYCLES 34 /* >= 2 us high */

/* A tick's output: its step events in time order, each the axes pulsed together and
 * the cycle (from the tick's compare match) at which the step is due on the
 * segment's profile. The layout is fixed: compare B's assembly addresses it. */
#define EV_MAX 40 /* events a tick holds (axes stepping within a slot share one): four
                   * axes apart at the advertised rate in the longest tick (790 us) */
#define AX_MAX 16 /* steps of one axis a tick holds (40000 steps/s in a 400 us tick) */
struct event {
    uint8_t mask; /* axes pulsed together; 0 ends a tick's list */
    uint16_t at;  /* cycles from the tick's compare match */
};
struct out {
    struct event ev[EV_MAX + 1]; /* offset 0, in time order */
    uint8_t n;
    uint8_t dir; /* axis bit set: negative */
    uint8_t own; /* the axes whose direction pins `dir` sets (the step engine sets its own) */
    uint8_t flags; /* OUT_* */
    uint8_t units; /* length of the tick */
    uint32_t seq;  /* OUT_SEG_END: the number of the segment it ends */
};
#define OUT_MOTION 0x01  /* a tick of motion (a segment, a dwell, homing) */
#define OUT_SEG_END 0x02 /* the tick ends a segment */
#define OUT_POS 0x04     /* positions were set (SET_POSITION, HOME) */
#define OUT_ABORT 0x08   /* a segment was abandoned */
/* The time wheel of the tick being computed: slot s holds the axes that step in
 * cycles [64 s, 64 s + 64) of the tick (a step goes out at its slot's middle, within
 * 2 us of its time); occ marks the slots in use, a bit each. Times on the wheel are
 * cycles x TIME_SCALE in 16 bits (a slot is their high byte), which covers the
 * longest tick (2 TICK_CYCLES - 1 unit). */
#define SLOT_CYCLES (256 / TIME_SCALE)
#define SLOTS (2 * TICK_CYCLES / SLOT_CYCLES)
extern uint8_t wheel[SLOTS];
extern uint8_t occ[(SLOTS + 7) / 8];
extern uint8_t occ_lo, occ_hi; /* the bytes of occ in use */
extern const uint8_t bit_of[8];
_Static_assert(SLOTS <= 255 && 2UL * TICK_CYCLES * TIME_SCALE < 65536UL,
               "slots and scaled times fit their types");


static inline __attribute__((always_inline)) void wheel_add(uint8_t slot, uint8_t bit)
{
    uint8_t w = wheel[slot];
    if (!w) {
        uint8_t byte = slot >> 3;
        occ[byte] |= bit_of[slot & 7];
        if (byte < occ_lo)
            occ_lo = byte;
        if (byte > occ_hi)
            occ_hi = byte;
    }
    wheel[slot] = w | bit;
}

/* The latest cycle of a tick of u units a step may be placed at: its pulse (high and
 * low) ends before the next tick's first. */
#define LAST_AT(u) ((uint16_t)((u) * UNIT_CYCLES - 2 * PULSE_CYCLES - 8))
#define LAST_SLOT(u) ((uint8_t)((LAST_AT(u) - SLOT_CYCLES / 2) / SLOT_CYCLES))

/* The tick's events from its wheel, in time order (and the wheel emptied); returns
 * the steps that found no room (never at the advertised rate). */
uint8_t wheel_take(struct out *o);
/* How much an axis's rate changes from one whole tick to the next (a segment's
 * acceleration): Q3.12 steps a tick, each tick, from the DDA's a (Q7.24); 0: steady. */
static inline __attribute__((always_inline)) int16_t bend_of(int32_t a)
{
    int32_t b = a >> 12;
    return b > 0x7FFF ? 0x7FFF : b < -0x7FFF ? -0x7FFF : (int16_t)b;
}

/* One step of an axis slower than one step a tick whose rate changes by `a` (bend_of,
 * scaled to this tick's span) over it (see step_wheel.c). */
void place_slow(uint8_t bit, uint32_t frac, uint32_t dist, uint16_t span, uint8_t last,
                int16_t a);
/* As place_steps over a tick of `span` cycles in which the axis's rate changes by `a`
 * (bend_of, per whole tick): each step where the tick's quadratic puts it (see
 * step_wheel.c). */
void place_steps_bent(uint8_t bit, uint8_t n, uint16_t f16, uint16_t c, uint8_t last,
                      int16_t a, uint16_t span);

/* The time (cycles x TIME_SCALE) of the first step of an axis that moves at c (cycles x
 * TIME_SCALE per step) and is `f16` (Q0.16) past its last step boundary: the distance to
 * the first crossing (1 - 2^-16 stands for 1) times c, the high half of the product */
static inline __attribute__((always_inline)) uint16_t first_step_at(uint16_t f16, uint16_t c)
{
    uint16_t x = f16 ? (uint16_t)-f16 : 0xFFFF;
    return (uint16_t)(mul16x16(x, c) >> 16);
}

/* A step at time t (cycles x TIME_SCALE; its slot is the high byte), no later than slot
 * `last` */
static inline __attribute__((always_inline)) void wheel_put(uint16_t t, uint8_t last, uint8_t bit)
{
    uint8_t slot = (uint8_t)(t >> 8);
    wheel_add(slot > last ? last : slot, bit);
}

/* Place n (>= 1) steps of axis `bit` on the wheel: the axis moves at c = cycles x
 * TIME_SCALE per step (< 2^16) and is `f16` (Q0.16) past its last step boundary at the
 * tick's start; step j (1..n) falls where the distance crosses j - f16, at
 * (j - f16) c / TIME_SCALE cycles. No step is placed after slot `last`. */
static inline __attribute__((always_inline)) void place_steps(uint8_t bit, uint8_t n,
                                                              uint16_t f16, uint16_t c,
                                                              uint8_t last)
{
    uint16_t t = first_step_at(f16, c);
    do {
        wheel_put(t, last, bit);
        t += c;
    } while (--n);
}


/* Steps of axis k over a tick of `span` cycles in which it moves `dist` (Q8.24),
 * starting `frac` (Q0.24) past its last step boundary, its rate changing by `a`
 * (bend_of, per whole tick); returns the steps over AX_MAX that were not placed (never
 * at the advertised rate). */
uint8_t place_axis(uint8_t k, uint8_t n, uint32_t frac, uint32_t dist, uint16_t span,
                   uint8_t last, int16_t a);

#endif
