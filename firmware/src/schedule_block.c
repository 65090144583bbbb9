#include <stdint.h>

#include "cdpr_reciprocals.h"
#include "mul16.h"
#include "schedule_block.h"
#include <avr/pgmspace.h>

_Static_assert(CDPR_RECIP_CYCLES_PER_TICK == F_CPU / CLOCK_HZ,
               "the table of reciprocals is for another cpu_hz / clock_hz");

/* The device's prediction of an axis's interval (PROTOCOL.md 5.5), where it makes one:
 * (D q[n] + 2^15) >> 16 with D 16 bits and q 32, as two 16 x 16 products (the low half's
 * carry taken into the high); else 0. */
static uint32_t guess_interval(uint32_t ticks, uint32_t n)
{
    if (n < 1 || n > CDPR_SCHED_PREDICT_MAX_STEPS || ticks > CDPR_SCHED_PREDICT_MAX_TICKS)
        return 0;
    uint32_t q = pgm_read_dword(&cdpr_reciprocals[n]);
    uint16_t d = (uint16_t)ticks;
    uint32_t low = mul16x16(d, (uint16_t)q) + 0x8000UL;
    return mul16x16(d, (uint16_t)(q >> 16)) + (low >> 16);
}

static int32_t rd_i32(struct reader *r)
{
    return unzigzag(rd_bounded(r, 32));
}

/* base + delta, or 0 outside 1..2^31 - 1 (refused), in 32 bits: base (a guess from
 * guess_interval, under 2^32, or a first interval, under 2^31) plus delta (-2^31..2^31 - 1)
 * lies in -2^31..2^33; the sum modulo 2^32 is the true one when it is in range, except
 * for a sum of 2^32 or more, which wraps below base with delta >= 0 */
static int32_t interval_of(uint32_t base, int32_t delta)
{
    uint32_t v = base + (uint32_t)delta;
    if (delta >= 0 && v < base)
        return 0;
    return v >= 1 && v <= (uint32_t)INT32_MAX ? (int32_t)v : 0;
}

/* The shortest of the `used` intervals a chunk sets (fixed point): they change linearly,
 * so it is at one end; 0 for an end below 0 (as the 64-bit form it replaces). In 32 bits:
 * interval 0..2^31 - 1 and used 1..65535 wherever the result counts (a count outside
 * 1..65535 is refused before the shortest is looked at, and a larger `used` only comes
 * with such a count), so with add < 0 the drop (used - 1) |add| is compared with
 * interval as |add|'s two 16-bit halves times used - 1: a high half's product of 2^15
 * or more drops past any interval. */
static int32_t chunk_shortest(int32_t interval, int32_t add, int32_t used)
{
    if (add >= 0 || used <= 1)
        return interval;
    uint32_t mag = 0u - (uint32_t)add; /* 1..2^31 */
    uint16_t n = (uint16_t)(used - 1);
    uint32_t high = mul16x16((uint16_t)(mag >> 16), n); /* < 2^15 * 2^16 below */
    if (used > 65536L || high >= 0x8000UL)
        return 0;
    uint32_t drop;
    if (__builtin_add_overflow(high << 16, mul16x16((uint16_t)mag, n), &drop) ||
        drop > (uint32_t)interval)
        return 0;
    return (int32_t)((uint32_t)interval - drop);
}

/* The first refusal of an axis wins: later ones leave the verdict as it is. */
static void refuse(struct sched_verdict *v, uint8_t axis, int32_t value)
{
    if (v->axis < 0) {
        v->axis = (int8_t)axis;
        v->value = value;
    }
}

void sched_parse(struct reader *r, uint32_t ticks, const uint32_t steps[CDPR_SCHED_AXES],
                 struct sched_verdict *verdict, struct sched_block *out)
{
    const int32_t shortest_allowed = (int32_t)MIN_STEP_INTERVAL_CYCLES << CDPR_SCHED_FRAC_BITS;
    uint8_t mask = rd_u8(r);
    if (r->err || !mask || mask >> CDPR_SCHED_AXES) {
        r->err = 1;
        return;
    }
    verdict->mask = mask;
    verdict->axis = -1;
    uint8_t used = 0;
#if STEP_ENGINE
    struct sched_block *sink = out;
    uint8_t over = 0;
#endif
    for (uint8_t k = 0; k < CDPR_SCHED_AXES; k++) {
        if (!(mask >> k & 1))
            continue;
        int32_t lead_c = rd_i32(r);
        int32_t interval = interval_of(guess_interval(ticks, steps[k]), rd_i32(r));
        int32_t add = rd_i32(r);
        uint8_t more = rd_u8(r);
#if STEP_ENGINE
        /* a block longer than the sink is read to its end, its chunks not kept: `used`
         * then says how many entries it takes (step_blocks.h, blocks_sink) */
        if (r->err || more >= CDPR_SCHED_MAX_CHUNKS) {
            r->err = 1;
            return;
        }
        if (out && used + 2 + more > out->capacity)
            out = 0, over = 1;
#else
        if (r->err || more >= CDPR_SCHED_MAX_CHUNKS ||
            (out && used + 2 + more > out->capacity)) {
            r->err = 1;
            return;
        }
#endif
        if (!steps[k])
            refuse(verdict, k, 0);
        /* interval / 2 (0..2^30 - 1) + lead_c (-2^31..2^31 - 1): overflows only upward */
        int32_t lead;
        if (__builtin_add_overflow(interval >> 1, lead_c, &lead))
            lead = INT32_MAX;
        /* |n| <= 2^31 - 1 less at most 31 counts of at most 65,535: no overflow */
        int32_t left = (int32_t)steps[k];
        int32_t shortest = 0;
        for (uint8_t i = 1; i <= more; i++) {
            int32_t count = (int32_t)rd_bounded(r, 16);
            int32_t c_int = interval_of((uint32_t)interval, rd_i32(r));
            int32_t c_add = rd_i32(r);
            if (r->err)
                return;
            left -= count;
            if (count < 1)
                refuse(verdict, k, count);
            if (c_int < 1)
                refuse(verdict, k, c_int);
            int32_t n_int = i < more ? count : count - 1; /* the last leads nowhere */
            int32_t s = n_int >= 1 ? chunk_shortest(c_int, c_add, n_int) : 0;
            if (s && (!shortest || s < shortest))
                shortest = s;
            if (out) {
                struct sched_chunk *c = &out->chunk[used + 1 + i];
                c->count = (uint16_t)count;
                c->interval = (uint32_t)c_int;
                c->add = c_add;
            }
        }
        /* the first chunk takes what the others leave of |n| */
        if (steps[k] && (left < 1 || left > (int32_t)CDPR_SCHED_MAX_COUNT))
            refuse(verdict, k, left);
        if (interval < 1)
            refuse(verdict, k, interval);
        if (lead < 0)
            refuse(verdict, k, lead);
        int32_t n_int = more ? left : left - 1;
        int32_t s = n_int >= 1 ? chunk_shortest(interval, add, n_int) : 0;
        if (s && (!shortest || s < shortest))
            shortest = s;
        if (shortest && shortest < shortest_allowed)
            refuse(verdict, k, shortest >> CDPR_SCHED_FRAC_BITS);
        if (out) {
            out->mask = mask;
            out->lead[k] = (uint32_t)lead;
            out->first[k] = used;
            out->chunks[k] = (uint8_t)(1 + more);
            out->chunk[used].count = (uint16_t)(1 + more); /* the axis's header */
            out->chunk[used].interval = (uint32_t)lead;
            out->chunk[used].add = 0;
            out->chunk[used + 1].count = (uint16_t)left;
            out->chunk[used + 1].interval = (uint32_t)interval;
            out->chunk[used + 1].add = add;
        }
        used = (uint8_t)(used + 2 + more);
        if (out)
            out->used = used;
    }
#if STEP_ENGINE
    if (over)
        sink->used = used; /* over its capacity: the entries it takes */
#endif
}

void sched_skip(struct reader *r)
{
    uint8_t mask = rd_u8(r);
    if (r->err || !mask || mask >> CDPR_SCHED_AXES) {
        r->err = 1;
        return;
    }
    for (; mask && !r->err; mask &= (uint8_t)(mask - 1)) {
        rd_skip(r, 32); /* the first edge, interval and add */
        rd_skip(r, 32);
        rd_skip(r, 32);
        uint8_t more = rd_u8(r);
        if (more >= CDPR_SCHED_MAX_CHUNKS)
            r->err = 1;
        for (; more && !r->err; more--) {
            rd_skip(r, 16); /* a chunk's count, interval and add */
            rd_skip(r, 32);
            rd_skip(r, 32);
        }
    }
}
