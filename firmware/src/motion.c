/* Every axis follows p(tau) = 2 r tau + (1 - 2 r) tau^2 over D ticks. The ISR
 * keeps, per axis, the steps due at tick i as floor(N p(i/D) + 1/2): it adds
 * v_i = N (p(i/D) - p((i-1)/D)) to an accumulator that starts at one half,
 * with v_i = v_1 + (i - 1) a, a = 2 N (1 - 2 r) / D^2. Step j thus falls on the
 * first tick at which N p crosses j - 1/2, the rule of firmware_protocol; the
 * last tick issues whatever fixed-point rounding left, so totals are exact. */
#include <stdlib.h>

#include "motion.h"
#include "protocol_gen.h"

#define Q24 16777216.0f

int8_t motion_rate_check(const struct segment *s, uint32_t *rate)
{
    /* rate = |n| * max(2r, 2 - 2r) * clock / D with r = c / 255, in integers:
     * |n| * F * clock > max * 255 * D with F = max(2c, 510 - 2c) (255 if constant) */
    uint16_t f;
    if (s->ramp < 0)
        f = 255;
    else
        f = (uint16_t)(s->ramp * 2 > 510 - s->ramp * 2 ? s->ramp * 2 : 510 - s->ramp * 2);
    for (uint8_t k = 0; k < 4; k++) {
        uint32_t n = (uint32_t)labs(s->deltas[k]);
        uint64_t lhs = (uint64_t)n * f * TICK_HZ;
        uint64_t rhs = (uint64_t)MAX_STEP_RATE * 255u * s->ticks;
        if (lhs > rhs) {
            uint64_t r = lhs / (255u * (uint64_t)s->ticks);
            *rate = r > 0x7FFFFFFF ? 0x7FFFFFFF : (uint32_t)r;
            return (int8_t)k;
        }
    }
    return -1;
}

void motion_prepare(struct item *it, const struct segment *s)
{
    float r = s->ramp < 0 ? 0.5f : (float)s->ramp / 255.0f;
    float inv_d = 1.0f / (float)s->ticks;
    float inv_d2 = inv_d * inv_d;
    uint8_t any = 0;
    it->kind = IT_SEG;
    it->ticks = s->ticks;
    it->flags = 0;
    for (uint8_t k = 0; k < 4; k++) {
        int32_t d = s->deltas[k];
        uint32_t n = (uint32_t)(d < 0 ? -(int64_t)d : d);
        float nf = (float)n;
        float a = 2.0f * nf * (1.0f - 2.0f * r) * inv_d2;
        float v1 = nf * (2.0f * r * inv_d + (1.0f - 2.0f * r) * inv_d2);
        it->u.seg.n[k] = n;
        it->u.seg.a[k] = (int32_t)(a * Q24);
        it->u.seg.v0[k] = (int32_t)((v1 - a) * Q24);
        if (d < 0)
            it->flags |= (uint8_t)(0x10 << k);
        if (n)
            any = 1;
    }
    if (s->ramp == SEG_RAMP_TO_REST || !any)
        it->flags |= SEGF_AT_REST;
}
