/* The time wheel (step_wheel.h): the slots, the scan that lists a tick's events,
 * and the placements that are not on the hot path. */
#include <avr/pgmspace.h>

#include "step_rate.h"
#include "step_wheel.h"

uint8_t wheel[SLOTS];
uint8_t occ[(SLOTS + 7) / 8];
uint8_t occ_lo = 0xFF, occ_hi; /* the bytes of occ in use */
const uint8_t bit_of[8] = {1, 2, 4, 8, 16, 32, 64, 128};
/* the lowest set bit of a byte, by table (the wheel's scan) */
#define LSB1(m) ((m) & 1 ? 0 : (m) & 2 ? 1 : (m) & 4 ? 2 : (m) & 8 ? 3 : (m) & 16 ? 4 : (m) & 32 ? 5 : (m) & 64 ? 6 : 7)
#define LSB4(m) LSB1(m), LSB1(m + 1), LSB1(m + 2), LSB1(m + 3)
#define LSB16(m) LSB4(m), LSB4(m + 4), LSB4(m + 8), LSB4(m + 12)
#define LSB64(m) LSB16(m), LSB16(m + 16), LSB16(m + 32), LSB16(m + 48)
static const uint8_t lsb_of[256] PROGMEM = {LSB64(0), LSB64(64), LSB64(128), LSB64(192)};

/* The tick's events from its wheel, in time order (and the wheel emptied). Slots
 * next to each other are one event, at the earlier one's time (within 3 us). */
uint8_t wheel_take(struct out *o)
{
    uint8_t lost = 0;
    struct event *e = o->ev, *last = 0;
    uint8_t n = 0, prev = 0xFE;
    uint8_t hi = occ_hi;
    for (uint8_t byte = occ_lo; byte <= hi; byte++) {
        uint8_t m = occ[byte];
        if (!m)
            continue;
        occ[byte] = 0;
        do {
            uint8_t slot = (uint8_t)((byte << 3) | pgm_read_byte(&lsb_of[m]));
            m &= (uint8_t)(m - 1);
            uint8_t axes = wheel[slot];
            wheel[slot] = 0;
            if ((uint8_t)(slot - 1) == prev) {
                last->mask |= axes; /* next to the last: together */
                continue;
            }
            prev = slot;
            if (n == EV_MAX) {
                for (; axes; axes &= (uint8_t)(axes - 1))
                    lost++; /* never at the advertised rate */
                continue;
            }
            last = e;
            e->mask = axes;
            e->at = (uint16_t)(mul8x8(slot, SLOT_CYCLES) + SLOT_CYCLES / 2);
            e++;
            n++;
        } while (m);
    }
    occ_lo = 0xFF;
    occ_hi = 0;
    e->mask = 0;
    o->n = n;
    return lost;
}

/* One step slower than 1953 steps/s (cycles x 8 per step >= 2^16: one step a tick at
 * most), at x / dist of the tick, x = 1 - frac: the fraction to 1/64 by halving
 * (no division), in 16 bits. */
void place_slow(uint8_t bit, uint32_t frac, uint32_t dist, uint16_t span, uint8_t last)
{
    uint32_t x32 = 0x1000000UL - frac;
    if (x32 > dist)
        x32 = dist; /* the crossing is within the tick (rounding aside) */
    if (!(uint16_t)(dist >> 16)) { /* under 1/256 step a tick: scale up (byte moves) */
        dist <<= 8;
        x32 <<= 8;
    }
    uint16_t d, x;
    if ((uint8_t)(dist >> 24)) {
        d = (uint16_t)(dist >> 16);
        x = (uint16_t)(x32 >> 16);
    } else {
        d = (uint16_t)(dist >> 8);
        x = (uint16_t)(x32 >> 8);
    }
    uint8_t f = 0;
    for (uint8_t i = 0; i < 6; i++) {
        d >>= 1;
        f <<= 1;
        if (x >= d) {
            x -= d;
            f |= 1;
        }
    }
    uint8_t slot = (uint8_t)(mul16x16((uint16_t)(2 * f + 1), span) >> 12); /* f + 1/2 */
    wheel_add(slot > last ? last : slot, bit);
}

/* Steps of axis k over a tick of `span` cycles in which it moves `dist` (Q8.24),
 * starting `frac` (Q0.24) past its last step boundary. */
uint8_t place_axis(uint8_t k, uint8_t n, uint32_t frac, uint32_t dist, uint16_t span,
                   uint8_t last)
{
    uint8_t lost = 0;
    uint16_t c = step_cycles8(dist, span);
    uint8_t bit = bit_of[k];
    if (n > AX_MAX) {
        lost = (uint8_t)(n - AX_MAX); /* never at the advertised rate */
        n = AX_MAX;
    }
    if (!c)
        place_slow(bit, frac, dist, span, last);
    else
        place_steps(bit, n, (uint16_t)(frac >> 8), c, last);
    return lost;
}
