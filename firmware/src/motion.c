/* Every axis follows p(tau) = 2 r tau + (1 - 2 r) tau^2 over the segment. On the
 * interrupt's grid of ticks (TICK_UNITS each, Dt = D / TICK_UNITS of them) the
 * steps due by the end of tick i are floor(N p(i / Dt) + 1/2): step j falls in
 * the tick in which N p crosses j - 1/2, the rule of firmware_protocol. With
 * A = 2 r N / Dt and B = (1 - 2 r) N / Dt^2, N p(i / Dt) = A i + B i^2, whose
 * first difference v_i = A + B (2 i - 1) grows by a = 2 B per tick: the
 * interrupt only adds (v += a, acc += v). The constants are computed here, in
 * the main loop, in single-precision floating point (relative error 2^-24) and
 * stored with 40 fraction bits; the last tick issues whatever is left, so the
 * totals are exact whatever the rounding. */
#include <avr/interrupt.h>

#include "config.h"
#include "motion.h"
#include "mul16.h"
#include "protocol_gen.h"
#include "step_rate.h"
#include "step_recip.h"
#include "step_blocks.h"

struct plan plans[PLAN_SLOTS];
volatile uint8_t plan_head, plan_tail;

uint8_t motion_cursor; /* next queue position to look at */

/* The rate test |n| F clock_hz / (255 D) > MAX_STEP_RATE, F = 255 max(2r, 2 - 2r),
 * becomes 100 |n| F > RATE_K100 D with an integer RATE_K100 (MAX_STEP_RATE a multiple
 * of 200). */
#define RATE_K100 (MAX_STEP_RATE * 255UL / (CLOCK_HZ / 100))
_Static_assert(RATE_K100 * (CLOCK_HZ / 100) == MAX_STEP_RATE * 255UL, "RATE_K100 must be exact");
/* The same for the four axes together (STEP_BUDGET, TOTAL_STEP_RATE; 0: no such test):
 * 100 (sum |n|) F > TOTAL_K100 D. */
#if TOTAL_STEP_RATE
#define TOTAL_K100 (TOTAL_STEP_RATE * 255UL / (CLOCK_HZ / 100))
_Static_assert(TOTAL_K100 * (CLOCK_HZ / 100) == TOTAL_STEP_RATE * 255UL, "TOTAL_K100 must be exact");
_Static_assert(TOTAL_K100 < 65536UL, "the fast test's 16 x 16-bit product");
#endif

/* |d| of a delta that is not INT32_MIN (the decoder refuses it) */
static inline uint32_t abs32(int32_t d)
{
    return (uint32_t)(d < 0 ? -d : d);
}

/* F of a segment's ramp: its peak speed over its mean, x 255 (255: steady) */
static inline __attribute__((always_inline)) uint16_t rate_factor(const struct segment *s)
{
    if (s->ramp < 0)
        return 255;
    return (uint16_t)(s->ramp * 2 > 510 - s->ramp * 2 ? s->ramp * 2 : 510 - s->ramp * 2);
}

/* A short fast segment (a print's, thousands a second): the exact test on the busiest
 * axis (`most` < 2^15 steps) in 16 x 16-bit products (100 n F < 2^31, F <= 510), and with
 * a total the summed steps the same way while the sum and D fit 16 bits (D < 2^16: 655 ms;
 * longer segments are few a second). 1: within the rates; 0: not decided here (the
 * per-axis search, rate_check_axes, then decides: it cost about 1,300 cycles a segment, a
 * sixth of the CPU at 2,000 segments/s). */
static inline __attribute__((always_inline)) uint8_t rate_fast_ok(uint16_t most, uint32_t sum,
                                                                  uint16_t f, uint32_t ticks)
{
    uint16_t f100 = (uint16_t)(f * 100U);
    (void)sum;
    if ((uint16_t)(ticks >> 16)) /* (RATE_K100 <= 51,000: 16 x 16 bits while D fits) */
        return 0;
    return mul16x16(most, f100) <= mul16x16((uint16_t)ticks, (uint16_t)RATE_K100)
#if TOTAL_STEP_RATE
           && !(uint8_t)(sum >> 16) &&
           mul16x16((uint16_t)sum, f100) <= mul16x16((uint16_t)ticks, (uint16_t)TOTAL_K100)
#endif
        ;
}
_Static_assert(RATE_K100 < 65536UL, "the fast test's 16 x 16-bit product");

/* motion_store's item from its flags and whether any axis moves */
static inline __attribute__((always_inline)) void finish_item(struct item *it,
                                                              const struct segment *s,
                                                              uint8_t flags, uint32_t any)
{
    uint8_t ramp = 0;
    if (s->ramp >= 0) {
        flags |= SEGF_RAMP;
        ramp = (uint8_t)s->ramp;
    }
    if (s->ramp == SEG_RAMP_TO_REST || !any)
        flags |= SEGF_AT_REST;
    it->kind = IT_SEG;
    it->ticks = s->ticks;
    it->flags = flags;
    it->ramp = ramp;
#if STEP_ENGINE
    it->blk_mask = 0;
    if (s->sched.mask)
        blocks_commit(it); /* read into the ring as the segment was decoded */
#endif
}

#if TOTAL_STEP_RATE
/* The four axes' steps summed against the total, in 64 bits (sum |n| < 2^33): 4 when
 * over (the summed peak rate in *rate), else -1. Every axis counts, one with a schedule
 * block too: the budget is the CPU's. Out of line, as rate_check_axes. */
static int8_t __attribute__((noinline)) rate_check_total(const struct segment *s, uint16_t f,
                                                          uint32_t *rate)
{
    /* 100 F <= 51000 <= TOTAL_FAST_K TOTAL_K100: a long slow segment passes on
     * TOTAL_FAST_K sum |n| <= D, without the 64-bit products */
#define TOTAL_FAST_K ((51000UL + TOTAL_K100 - 1) / TOTAL_K100)
    _Static_assert(TOTAL_FAST_K <= 64, "the fast test's bound");
    uint64_t n = 0;
    for (uint8_t k = 0; k < 4; k++)
        n += abs32(s->deltas[k]);
    if (n < (1UL << 24) && (uint32_t)n * TOTAL_FAST_K <= s->ticks)
        return -1;
    if (n * f * 100U <= (uint64_t)s->ticks * TOTAL_K100)
        return -1;
    float fn = 0.0f; /* the sum again, in float: no 64-bit conversion (124 B of library) */
    for (uint8_t k = 0; k < 4; k++)
        fn += (float)abs32(s->deltas[k]);
    float r = fn * (float)f * (float)CLOCK_HZ / (255.0f * (float)s->ticks);
    *rate = r > 2147483647.0f ? 0x7FFFFFFFUL : (uint32_t)r;
    return CDPR_STEP_RATE_ALL_AXES;
}
#define AXES_PASSED(s, f, rate) rate_check_total(s, f, rate)
#else
#define AXES_PASSED(s, f, rate) (-1)
#endif

/* Each axis against the rate, in 64 bits where the figures need them: the axis over
 * (its peak rate in *rate), else the four together against the total (AXES_PASSED), or
 * -1. Out of line: its frame would cost the fast test. */
static int8_t __attribute__((noinline)) rate_check_axes(const struct segment *s, uint16_t f,
                                                         uint32_t *rate)
{
    /* 100 F <= 51000 <= FAST_K RATE_K100: no axis is over when FAST_K max|n| <= D,
     * decided without the per-axis products */
#define FAST_K ((51000UL + RATE_K100 - 1) / RATE_K100)
    _Static_assert(FAST_K * RATE_K100 >= 51000UL && FAST_K <= 64, "the fast test's bound");
    uint32_t most = abs32(s->deltas[0]) | abs32(s->deltas[1]) | abs32(s->deltas[2]) |
                    abs32(s->deltas[3]); /* >= max |n|, < 2 max |n| */
    if (most < (1UL << 24) && most * FAST_K <= s->ticks)
        return AXES_PASSED(s, f, rate);
    for (uint8_t k = 0; k < 4; k++) {
        if (s->sched.mask >> k & 1)
            continue; /* its schedule block decides (schedule_block.h) */
        int32_t d = s->deltas[k];
        uint32_t n = (uint32_t)(d < 0 ? -(int64_t)d : d);
        /* 100 n F < 2^32 when n < 2^16 (a fast segment of a print); else 64 bits */
        uint8_t over;
        if (n < (1UL << 16))
            over = (uint64_t)(n * f * 100UL) > (uint64_t)s->ticks * RATE_K100;
        else
            over = (uint64_t)n * f * 100U > (uint64_t)s->ticks * RATE_K100;
        if (over) {
            float r = (float)n * (float)f * (float)CLOCK_HZ / (255.0f * (float)s->ticks);
            *rate = r > 2147483647.0f ? 0x7FFFFFFFUL : (uint32_t)r;
            return (int8_t)k;
        }
    }
    return AXES_PASSED(s, f, rate);
}

int8_t motion_rate_check(const struct segment *s, uint32_t *rate)
{
    uint16_t f = rate_factor(s), n = 0;
    uint32_t sum = 0;
    for (uint8_t k = 0; k < 4; k++) {
        uint32_t a = abs32(s->deltas[k]);
        if (a & 0xFFFF8000UL) /* a mask: -Os shifts 15 times in a loop */
            return rate_check_axes(s, f, rate);
        if ((uint16_t)a > n)
            n = (uint16_t)a;
        sum += (uint16_t)a;
    }
    return rate_fast_ok(n, sum, f, s->ticks) ? -1 : rate_check_axes(s, f, rate);
}

/* The item of a segment, and (`check`) its rate test in the same pass over the axes:
 * thousands of segments a second, so no 64-bit negation (the decoder refuses INT32_MIN),
 * no variable shifts, the flags in a register (should the item and the segment alias,
 * every |= would be a load and a store). 0: `check` found it over (the item written in
 * part). */
static inline __attribute__((always_inline)) uint8_t store_item(struct item *it,
                                                                const struct segment *s,
                                                                uint8_t check)
{
    uint8_t flags = 0, bit = 0x10, wide = 0;
    uint16_t most = 0;
    uint32_t any = 0, sum = 0;
    for (uint8_t k = 0; k < 4; k++, bit <<= 1) {
        int32_t d = s->deltas[k];
        uint32_t n = abs32(d);
        if (d < 0)
            flags |= bit;
        any |= n;
        it->u.n[k] = n;
        if (n & 0xFFFF8000UL) {
            wide = 1;
        } else {
            if ((uint16_t)n > most)
                most = (uint16_t)n;
            sum += (uint16_t)n;
        }
    }
    uint32_t rate;
    if (check && (wide || !rate_fast_ok(most, sum, rate_factor(s), s->ticks)) &&
        motion_rate_check(s, &rate) >= 0)
        return 0;
    finish_item(it, s, flags, any);
    return 1;
}

void motion_store(struct item *it, const struct segment *s)
{
    store_item(it, s, 0);
}

uint8_t motion_store_checked(struct item *it, const struct segment *s)
{
    return store_item(it, s, 1);
}

uint32_t motion_ticks_of(uint32_t units, uint8_t *last_units)
{
    if (units < TICK_UNITS) {
        *last_units = (uint8_t)units;
        return 1;
    }
    uint32_t ticks = units / TICK_UNITS;
    *last_units = (uint8_t)(units - (ticks - 1) * TICK_UNITS);
    return ticks;
}

/* A per-segment constant K as floor(|K| 2^40) (48 bits: lo, the low 16, and hi, the
 * next 32) and its sign: one float conversion per segment shape; per axis only
 * integer products follow. */
struct fx40 {
    uint16_t lo;
    uint32_t hi;
    uint8_t neg;
};

static struct fx40 fx40_of(float k)
{
    struct fx40 f;
    f.neg = k < 0.0f;
    uint64_t v = (uint64_t)((f.neg ? -k : k) * 1099511627776.0f); /* 2^40 */
    f.lo = (uint16_t)v;
    f.hi = (uint32_t)(v >> 16);
    return f;
}

/* the same for n >= 2^16 (a long segment): 64-bit arithmetic, out of the common path */
static void __attribute__((noinline)) times_fx40_wide(uint32_t n, const struct fx40 *k, uint16_t *l,
                                                      uint32_t *h)
{
    uint64_t v = (uint64_t)n * (((uint64_t)k->hi << 16) | k->lo);
    *l = (uint16_t)v;
    *h = (uint32_t)(v >> 16);
}

static uint32_t __attribute__((noinline)) times_frac32_wide(uint32_t n, uint32_t p)
{
    return (uint32_t)(((uint64_t)n * p + 0x80000000UL) >> 32);
}

/* n K in Q40 as the interrupt's pair (lo: 16 fraction bits, hi: Q8.24), modulo 2^48
 * (the value fits: a segment that passed the rate check moves a few steps a tick).
 * Three 16 x 16-bit products when n < 2^16 (every segment of a print). */
static inline __attribute__((always_inline)) void times_fx40(uint32_t n, const struct fx40 *k, uint16_t *lo, int32_t *hi)
{
    uint16_t l;
    uint32_t h;
    if (n >> 16) {
        times_fx40_wide(n, k, &l, &h);
    } else {
        uint16_t n16 = (uint16_t)n;
        uint32_t r0 = mul16x16(n16, k->lo);
        uint32_t r1 = mul16x16(n16, (uint16_t)k->hi);
        uint16_t r2 = (uint16_t)(n16 * (uint16_t)(k->hi >> 16)); /* its low half counts */
        l = (uint16_t)r0;
        h = (r0 >> 16) + r1 + ((uint32_t)r2 << 16);
    }
    if (k->neg) {
        l = (uint16_t)-l;
        h = ~h + (l == 0);
    }
    *lo = l;
    *hi = (int32_t)h;
}

/* round(n P) for P = floor(P 2^32) / 2^32 in [0, 1) */
static inline __attribute__((always_inline)) uint32_t times_frac32(uint32_t n, uint32_t p)
{
    if (n >> 16)
        return times_frac32_wide(n, p);
    uint16_t n16 = (uint16_t)n;
    uint32_t t = mul16x16(n16, (uint16_t)(p >> 16)) + (mul16x16(n16, (uint16_t)p) >> 16);
    return (t + 0x8000UL) >> 16;
}

/* floor(n (ka i + kb i^2) + 1/2): the steps due by the end of tick i */
uint32_t motion_steps_due(float n, float ka, float kb, uint32_t i)
{
    float t = (float)i;
    float q = n * (ka * t + kb * t * t) + 0.5f;
    return q <= 0.0f ? 0 : (uint32_t)q;
}

/* What all axes of a segment share: a handful of float operations, done again only
 * when the duration or the ramp changes (a cruise repeats them). Per axis the work
 * is integer: n times each constant. */
static struct {
    uint32_t units;
    uint8_t ramp, flags;
    float ka, kb;
    uint8_t accel;     /* kb != 0 */
    struct fx40 v0, a; /* ka - kb, 2 kb */
    uint32_t before;   /* (ka T' + kb T'^2) 2^32, T' = ticks - 1 */
    uint32_t ticks;
    uint8_t last_units;
} shape;

/* The constants of an axis of n < MEMO_N steps in the current shape, kept as they are
 * computed: short segments (thousands a second) move each axis by a few steps, so
 * the same small n comes back again and again while the shape stays (a cruise).
 * An entry is valid while its gen is the shape's (0: never). */
#define MEMO_N 8
static struct {
    uint16_t v_lo, a_lo, period;
    int32_t v_hi, a_hi;
    uint8_t last_n, est_low, gen;
} memo[MEMO_N];
static uint8_t shape_gen;

static void shape_of(const struct item *it)
{
    uint8_t ramp_flag = it->flags & SEGF_RAMP;
    if (shape.units == it->ticks && shape.flags == ramp_flag && shape.ramp == it->ramp)
        return;
    if (!++shape_gen) { /* wrapped: forget the entries of 256 shapes ago */
        for (uint8_t i = 0; i < MEMO_N; i++)
            memo[i].gen = 0;
        shape_gen = 1;
    }
    shape.units = it->ticks;
    shape.flags = ramp_flag;
    shape.ramp = it->ramp;
    float r = ramp_flag ? (float)it->ramp * (1.0f / 255.0f) : 0.5f;
    float inv = (float)TICK_UNITS / (float)it->ticks; /* 1 / Dt */
    float ka = 2.0f * r * inv, kb = (1.0f - 2.0f * r) * inv * inv;
    shape.ka = ka;
    shape.kb = kb;
    shape.accel = kb != 0.0f;
    shape.ticks = motion_ticks_of(it->ticks, &shape.last_units);
    float t = (float)(shape.ticks - 1);
    /* the interrupt adds a before it uses v: start one a early */
    shape.v0 = fx40_of(ka - kb);
    shape.a = fx40_of(2.0f * kb);
    float before = ka * t + kb * t * t;
    shape.before = before >= 1.0f ? 0xFFFFFFFFUL : before <= 0.0f ? 0 : (uint32_t)(before * 4294967296.0f);
}

/* An axis of n > 0 steps whose constants are not kept: the products, out of the
 * common path */
static void __attribute__((noinline)) axis_constants(struct axis_plan *x, uint32_t n, uint8_t accel)
{
    uint32_t before = times_frac32(n, shape.before);
    if (before > n)
        before = n;
    x->last_n = n - before;
    x->est_low = (uint8_t)before;
    times_fx40(n, &shape.v0, &x->v_lo, &x->v_hi);
    times_fx40(n, &shape.a, &x->a_lo, &x->a_hi);
    if (STEP_ENGINE && !accel)
        x->interval = step_interval(n, shape.units);
    /* a steady segment moves v_hi every tick: the interrupt's step rate, now */
    x->period = accel ? 0 : step_period((uint32_t)x->v_hi, TICK_CYCLES);
    if (n < MEMO_N) {
        memo[n].v_lo = x->v_lo;
        memo[n].v_hi = x->v_hi;
        memo[n].a_lo = x->a_lo;
        memo[n].a_hi = x->a_hi;
        memo[n].last_n = (uint8_t)x->last_n;
        memo[n].est_low = x->est_low;
        memo[n].period = x->period;
        memo[n].gen = shape_gen;
    }
}

#if STEP_ENGINE
/* What the plan before the next one leaves the step tick: the axes its DDA may drive in
 * its last tick (those it steps without a chunk, and those the dispatch may hand back to
 * the DDA, below) and their directions; 0xFF, unknown, after a flush or an item that is
 * not a segment (a homing's ticks are the DDA's). */
static uint8_t dda_after = 0xFF, dir_after;
#endif

static void prepare(struct plan *p, const struct item *it, uint8_t index)
{
    shape_of(it);
    uint8_t dir = it->flags >> 4, moving = 0, bit = 1;
    p->index = index;
    p->dir = dir;
    p->accel = shape.accel;
    p->at_rest = it->flags & SEGF_AT_REST;
    p->ticks = shape.ticks;
    p->last_units = shape.last_units;
    p->ka = shape.ka;
    p->kb = shape.kb;
    const uint32_t *np = it->u.n;
    /* The dispatch hands an engine axis back to the DDA if the DDA drove it in the tick
     * before and it reverses (stepper.c): those keep the DDA's constants; a steady
     * segment's other axes, the engine's throughout, need only their interval (about
     * 2,000 cycles of a plan's 3,400 when n is not kept in the memo). */
    uint8_t risk = 0x0F, lean = 0;
#if STEP_ENGINE
    if (dda_after != 0xFF)
        risk = dda_after & (uint8_t)(dir ^ dir_after);
    if (!p->accel)
        lean = (uint8_t)~risk & 0x0F; /* (of the moving axes) */
#endif
    struct axis_plan *x = p->ax;
    int32_t *delta = p->delta;
    for (; bit != 0x10; bit <<= 1, x++, np++, delta++) {
        uint32_t n = *np;
        *delta = (dir & bit) ? -(int32_t)n : (int32_t)n;
        x->acc = 1UL << 23;
        x->period = 0;
        if (!n) {
            x->v_hi = x->a_hi = 0;
            x->v_lo = x->a_lo = 0;
            x->last_n = 0;
            x->est_low = 0;
            continue;
        }
        moving |= bit;
        if (n < MEMO_N && memo[n].gen == shape_gen) {
            if (STEP_ENGINE && (lean & bit)) {
                /* its interval alone (a steady shape's memo holds it in a_hi's place) */
                x->interval = (uint32_t)memo[n].a_hi;
                continue;
            }
            x->v_lo = memo[n].v_lo;
            x->v_hi = memo[n].v_hi;
            x->a_lo = memo[n].a_lo;
            x->a_hi = memo[n].a_hi;
            x->last_n = memo[n].last_n;
            x->est_low = memo[n].est_low;
            x->period = memo[n].period;
        } else if (STEP_ENGINE && (lean & bit) && n >= MEMO_N) {
            /* the chunk's interval alone (a small n's constants go to the memo: kept, the
             * memo's interval costs less than the interval computed again) */
            x->interval = step_interval(n, shape.units);
        } else {
            axis_constants(x, n, p->accel);
        }
    }
    p->moving = moving;
#if STEP_ENGINE
    /* the step engine's axes: a steady segment's (each one chunk, its interval predicted
     * or from its block), a ramp's with a schedule block; the DDA steps the rest (an
     * axis the host left without a block: PROTOCOL.md 5.5, 3.0's rule) */
    uint8_t engine = p->accel ? (uint8_t)(it->blk_mask & moving) : moving;
    dda_after = (uint8_t)((moving & (uint8_t)~engine) | (engine & risk));
    dir_after = dir;
    p->blk_mask = (uint8_t)((it->blk_mask & moving) | (lean & moving) << 4);
    p->blk_at = it->blk_at;
    p->blk_end = it->blk_end;
    p->engine = engine;
#else
    (void)risk;
    (void)lean;
#endif
}

void motion_plans_reset(void)
{
#if STEP_ENGINE
    dda_after = 0xFF;
#endif
    uint8_t s = SREG;
    cli();
    plan_head = plan_tail = 0;
    motion_cursor = queue_head;
    SREG = s;
}

void motion_prepare_some(uint8_t budget)
{
    uint8_t head = queue_head, tail = queue_tail;
    /* the interrupt may have completed items the cursor had not reached yet */
    if ((uint8_t)(motion_cursor - tail) > (uint8_t)(head - tail))
        motion_cursor = tail;
    while (motion_cursor != head && (uint8_t)(plan_head - plan_tail) < PLAN_SLOTS && budget) {
        const struct item *it = queue_slot(motion_cursor);
        if (it->kind == IT_SEG) {
            prepare(&plans[plan_head & (PLAN_SLOTS - 1)], it, motion_cursor);
            cli();
            plan_head++;
            sei();
            budget--;
        }
#if STEP_ENGINE
        else
            dda_after = 0xFF; /* (a homing's ticks, a dwell: the DDA's last tick unknown) */
#endif
        motion_cursor++;
    }
}
