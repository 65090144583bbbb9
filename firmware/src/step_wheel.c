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

/* One step slower than 977 steps/s (cycles x 4 per step >= 2^16: under one step in
 * the longest tick), at x / dist of the tick, x = 1 - frac: the fraction to 1/64 by
 * halving (no division), in 16 bits. */
/* x / d for x <= d, in `bits` bits (1 - 2^-bits stands for 1), by halving */
static uint8_t ratio(uint16_t x, uint16_t d, uint8_t bits)
{
    uint8_t f = 0;
    for (; bits; bits--) {
        d >>= 1;
        f <<= 1;
        if (x >= d) {
            x -= d;
            f |= 1;
        }
    }
    return f;
}

void place_slow(uint8_t bit, uint32_t frac, uint32_t dist, uint16_t span, uint8_t last,
                int16_t a)
{
    uint32_t x32 = 0x1000000UL - frac;
    if (x32 > dist)
        x32 = dist; /* the crossing is within the tick (rounding aside) */
    /* the bend g = a / (2 dist), at most 1 */
    uint8_t speeding = a > 0;
    uint32_t y32 = (uint32_t)(uint16_t)(speeding ? a : -a) << 11;
    if (y32 > dist)
        y32 = dist;
    if (!(uint16_t)(dist >> 16)) { /* under 1/256 step a tick: scale up (byte moves) */
        dist <<= 8;
        x32 <<= 8;
        y32 <<= 8;
    }
    uint16_t d, x, y;
    if ((uint8_t)(dist >> 24)) {
        d = (uint16_t)(dist >> 16);
        x = (uint16_t)(x32 >> 16);
        y = (uint16_t)(y32 >> 16);
    } else {
        d = (uint16_t)(dist >> 8);
        x = (uint16_t)(x32 >> 8);
        y = (uint16_t)(y32 >> 8);
    }
    /* the crossing at f / 128 of the tick at the tick's mean rate; a changing rate
     * moves it by g f (128 - f) / 128 (the quadratic's first-order root) */
    uint8_t f = ratio(x, d, 7);
    if (y) {
        uint8_t g = ratio(y, d, 6); /* g, Q0.6 */
        uint8_t bend = (uint8_t)(mul16x16(mul8x8(f, (uint8_t)(128 - f)), g) >> 13);
        f = speeding ? (uint8_t)(f + bend) : (uint8_t)(f - bend);
    }
    /* (f + 1/2) / 128 of the span, in slots of 64 cycles */
    _Static_assert(SLOT_CYCLES == 64, "a slot is span >> 14 of (2 f + 1) span");
    uint8_t slot = (uint8_t)(mul16x16((uint16_t)(2 * f + 1), span) >> 14);
    wheel_add(slot > last ? last : slot, bit);
}

/* A tick of S (cycles x TIME_SCALE) in which the axis moves v steps and its rate
 * changes by a_S (the second difference of its position at ticks of S): the distance
 * after t is v t / S - (a_S / 2) (t / S) (1 - t / S), so a crossing that the mean rate
 * puts at t0 comes at t0 + g t0 (S - t0) / S, g = a_S / (2 v) (to first order; |g| <= 1
 * keeps the steps in order). With c = S / v and a_S = a (S / T)^2, a the bend of whole
 * ticks of T = BEND_T, the shift is a c t0 (S - t0) / (2 T^2) whatever S is. In fixed
 * point: h = |a| c / 2^16 (a in Q.12) = g T^2 / (8 S), and the shift =
 * (t0 (S - t0) / 2^16) (h BEND_K / 2^16) / 2^8, BEND_K = 2^43 / T^2. */
#define BEND_T ((uint32_t)TICK_CYCLES * TIME_SCALE)
#define BEND_K ((uint16_t)((1ULL << 43) / ((uint64_t)BEND_T * BEND_T)))
_Static_assert(BEND_T < 65536UL && BEND_K > 1000, "the bend's fixed point");

void place_steps_bent(uint8_t bit, uint8_t n, uint16_t f16, uint16_t c, uint8_t last,
                      int16_t a, uint16_t span)
{
    uint8_t speeding = a > 0;
    uint16_t s = (uint16_t)(span * TIME_SCALE);
    uint32_t hc = mul16x16((uint16_t)(speeding ? a : -a), c) >> 16;
    /* g <= 1: h <= T^2 / (8 S), T / 8 for a whole tick, T / 16 for a longer last one */
    uint16_t hmax = s == BEND_T ? BEND_T / 8 : BEND_T / 16;
    if (hc > hmax)
        hc = hmax;
    uint16_t m = (uint16_t)(mul16x16((uint16_t)hc, BEND_K) >> 16);
    uint16_t t = first_step_at(f16, c);
    do {
        uint16_t u = t < s ? (uint16_t)(s - t) : 0;
        uint16_t p = (uint16_t)(mul16x16(t, u) >> 16);
        uint16_t shift = (uint16_t)(mul16x16(p, m) >> 8);
        wheel_put(speeding ? t + shift : t - shift, last, bit);
        t += c;
    } while (--n);
}

/* Steps of axis k over a tick of `span` cycles in which it moves `dist` (Q8.24),
 * starting `frac` (Q0.24) past its last step boundary, its rate changing by `a`. */
#define TICK_SLOTS (TICK_CYCLES / SLOT_CYCLES)
#define SQUARE_Q8 ((uint16_t)((256UL * 65536UL) / (TICK_SLOTS * TICK_SLOTS)))
_Static_assert(TICK_CYCLES % SLOT_CYCLES == 0 && SQUARE_Q8 > 1000, "a tick's span squared");
uint8_t place_axis(uint8_t k, uint8_t n, uint32_t frac, uint32_t dist, uint16_t span,
                   uint8_t last, int16_t a)
{
    uint8_t lost = 0;
    uint16_t c = step_period(dist, span);
    uint8_t bit = bit_of[k];
    if (n > AX_MAX) {
        lost = (uint8_t)(n - AX_MAX); /* never at the advertised rate */
        n = AX_MAX;
    }
    if (!c) {
        /* the bend at this tick's span: a (span / TICK_CYCLES)^2, the square in Q8 */
        uint8_t r = (uint8_t)(span / SLOT_CYCLES);
        uint16_t q = (uint16_t)(mul16x16(mul8x8(r, r), SQUARE_Q8) >> 16);
        uint32_t m = mul16x16((uint16_t)(a < 0 ? -a : a), q) >> 8;
        int16_t as = m > 0x7FFF ? 0x7FFF : (int16_t)m; /* (past g = 1 anyway) */
        place_slow(bit, frac, dist, span, last, a < 0 ? -as : as);
    } else if (a) {
        place_steps_bent(bit, n, (uint16_t)(frac >> 8), c, last, a, span);
    } else {
        place_steps(bit, n, (uint16_t)(frac >> 8), c, last);
    }
    return lost;
}
