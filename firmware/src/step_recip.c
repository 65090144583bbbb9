/* The table of reciprocals (step_recip.h), computed by the compiler. */
#include "step_recip.h"
#include "config.h"
#include "mul16.h"

#define RECIP_NUM ((unsigned long long)UNIT_CYCLES << 24)
#define Q1(n) ((uint32_t)((2ULL * RECIP_NUM + (n)) / (2ULL * (n))))
#define Q4(n) Q1(n), Q1(n + 1), Q1(n + 2), Q1(n + 3)
#define Q16(n) Q4(n), Q4(n + 4), Q4(n + 8), Q4(n + 12)
#define Q64(n) Q16(n), Q16(n + 16), Q16(n + 32), Q16(n + 48)
#define Q256(n) Q64(n), Q64(n + 64), Q64(n + 128), Q64(n + 192)
const uint32_t step_recip[PREDICT_MAX_STEPS + 1] PROGMEM = {
    0, Q256(1), Q256(257), Q256(513), Q64(769), Q64(833), Q64(897), Q16(961), Q16(977),
    Q16(993), Q4(1009), Q4(1013), Q4(1017), Q4(1021)};
_Static_assert(sizeof step_recip == 4 * (PREDICT_MAX_STEPS + 1), "the table's size");

uint32_t step_interval(uint32_t n, uint32_t ticks)
{
    if (n <= PREDICT_MAX_STEPS && ticks <= PREDICT_MAX_TICKS) {
        uint32_t q = pgm_read_dword(&step_recip[n]);
        uint16_t d = (uint16_t)ticks;
        /* (D q + 2^15) >> 16 = D q_hi + (D q_lo + 2^15) >> 16: two 16 x 16 products */
        return mul16x16(d, (uint16_t)(q >> 16)) + ((mul16x16(d, (uint16_t)q) + 0x8000UL) >> 16);
    }
    /* a long segment (the host sends its schedule with protocol 3): exact to rounding */
    if (ticks < 0xFFFFFFFFUL / (UNIT_CYCLES << 8))
        return (ticks * (UNIT_CYCLES << 8) + n / 2) / n;
    unsigned long long num = (unsigned long long)ticks * (UNIT_CYCLES << 8);
    return (uint32_t)((num + n / 2) / n);
}
