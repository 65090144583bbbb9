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
#include <math.h>

#include "config.h"
#include "motion.h"
#include "protocol_gen.h"

struct plan plans[PLAN_SLOTS];
volatile uint8_t plan_head, plan_tail;
static uint8_t cursor; /* next queue position to look at */

/* The rate test |n| F clock_hz / (255 D) > MAX_STEP_RATE, F = 255 max(2r, 2 - 2r),
 * becomes |n| F > RATE_K D with an integer RATE_K. */
#define RATE_K (MAX_STEP_RATE * 255UL / CLOCK_HZ)
_Static_assert(RATE_K * CLOCK_HZ == MAX_STEP_RATE * 255UL, "RATE_K must be exact");

int8_t motion_rate_check(const struct segment *s, uint32_t *rate)
{
    uint16_t f;
    if (s->ramp < 0)
        f = 255;
    else
        f = (uint16_t)(s->ramp * 2 > 510 - s->ramp * 2 ? s->ramp * 2 : 510 - s->ramp * 2);
    /* D * RATE_K, saturated: a longer segment cannot be too fast for 32-bit step counts */
    uint32_t limit = s->ticks > 0xFFFFFFFFUL / RATE_K ? 0xFFFFFFFFUL : s->ticks * RATE_K;
    for (uint8_t k = 0; k < 4; k++) {
        int32_t d = s->deltas[k];
        uint32_t n = (uint32_t)(d < 0 ? -(int64_t)d : d);
        uint8_t over;
        if (n < (1UL << 22))
            over = n * f > limit; /* < 2^31: no overflow */
        else
            over = (uint64_t)n * f > (uint64_t)s->ticks * RATE_K;
        if (over) {
            float r = (float)n * (float)f * (float)CLOCK_HZ / (255.0f * (float)s->ticks);
            *rate = r > 2147483647.0f ? 0x7FFFFFFFUL : (uint32_t)r;
            return (int8_t)k;
        }
    }
    return -1;
}

void motion_store(struct item *it, const struct segment *s)
{
    uint8_t any = 0;
    it->kind = IT_SEG;
    it->ticks = s->ticks;
    it->flags = 0;
    it->ramp = 0;
    if (s->ramp >= 0) {
        it->flags |= SEGF_RAMP;
        it->ramp = (uint8_t)s->ramp;
    }
    for (uint8_t k = 0; k < 4; k++) {
        int32_t d = s->deltas[k];
        it->u.n[k] = (uint32_t)(d < 0 ? -(int64_t)d : d);
        if (d < 0)
            it->flags |= (uint8_t)(0x10 << k);
        if (d)
            any = 1;
    }
    if (s->ramp == SEG_RAMP_TO_REST || !any)
        it->flags |= SEGF_AT_REST;
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

/* x as 48-bit fixed point: hi = floor(x 2^24), lo = the next 16 fraction bits */
static void fixed48(float x, int32_t *hi, uint16_t *lo)
{
    float s = x * 16777216.0f;
    float f = floorf(s);
    *hi = (int32_t)f;
    *lo = (uint16_t)((s - f) * 65536.0f);
}

/* floor(n (ka i + kb i^2) + 1/2): the steps due by the end of tick i */
uint32_t motion_steps_due(float n, float ka, float kb, uint32_t i)
{
    float t = (float)i;
    float q = n * (ka * t + kb * t * t) + 0.5f;
    return q <= 0.0f ? 0 : (uint32_t)q;
}

static void prepare(struct plan *p, const struct item *it, uint8_t index)
{
    float r = (it->flags & SEGF_RAMP) ? (float)it->ramp / 255.0f : 0.5f;
    float inv = (float)TICK_UNITS / (float)it->ticks; /* 1 / Dt */
    float ka = 2.0f * r * inv, kb = (1.0f - 2.0f * r) * inv * inv;
    p->index = index;
    p->dir = it->flags >> 4;
    p->moving = 0;
    p->accel = kb != 0.0f;
    p->at_rest = it->flags & SEGF_AT_REST;
    p->ticks = motion_ticks_of(it->ticks, &p->last_units);
    p->ka = ka;
    p->kb = kb;
    for (uint8_t k = 0; k < 4; k++) {
        struct axis_plan *x = &p->ax[k];
        uint32_t n = it->u.n[k];
        float nf = (float)n;
        p->delta[k] = (p->dir >> k & 1) ? -(int32_t)n : (int32_t)n;
        uint32_t before = motion_steps_due(nf, ka, kb, p->ticks - 1);
        if (before > n)
            before = n;
        x->last_n = n - before;
        x->est_low = (uint8_t)before;
        x->acc = 1UL << 23;
        if (n)
            p->moving |= (uint8_t)(1 << k);
        /* the interrupt adds a before it uses v: start one a early */
        fixed48(nf * (ka - kb), &x->v_hi, &x->v_lo);
        fixed48(2.0f * nf * kb, &x->a_hi, &x->a_lo);
    }
}

void motion_plans_reset(void)
{
    uint8_t s = SREG;
    cli();
    plan_head = plan_tail = 0;
    cursor = queue_head;
    SREG = s;
}

void motion_prepare_ahead(void)
{
    uint8_t head = queue_head, tail = queue_tail;
    /* the interrupt may have completed items the cursor had not reached yet */
    if ((uint8_t)(cursor - tail) > (uint8_t)(head - tail))
        cursor = tail;
    while (cursor != head && (uint8_t)(plan_head - plan_tail) < PLAN_SLOTS) {
        const struct item *it = queue_slot(cursor);
        if (it->kind == IT_SEG) {
            prepare(&plans[plan_head & (PLAN_SLOTS - 1)], it, cursor);
            cli();
            plan_head++;
            sei();
        }
        cursor++;
    }
}
