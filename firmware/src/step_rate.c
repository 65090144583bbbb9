/* How fast an axis steps: cycles per step from the distance it moves in a tick,
 * without a division (the step interrupt and the plans ahead of it). */
#include <avr/pgmspace.h>

#include "mul16.h"
#include "step_rate.h"

/* 2^22 / (m + 1/2) for m = 128..255: the reciprocal of a normalised distance, to
 * 0.4 % (a step placed within 0.4 % of the tick's length, 0.4 us). */
#define R1(m) ((uint16_t)((4194304UL * 2 + (2 * (m) + 1) / 2) / (2 * (m) + 1)))
#define R4(m) R1(m), R1(m + 1), R1(m + 2), R1(m + 3)
#define R16(m) R4(m), R4(m + 4), R4(m + 8), R4(m + 12)
static const uint16_t recip_table[128] PROGMEM = {
    R16(128), R16(144), R16(160), R16(176), R16(192), R16(208), R16(224), R16(240)};

/* Cycles per step times 4 for an axis that moves `dist` steps (Q8.24) in `span`
 * cycles, span 2^26 / dist, from the table (no division in the interrupt); 0 when
 * that is 2^16 or more (slower than one step per 16384 cycles). The distance is taken
 * to 12 fraction bits: steps faster than that are at least 0.39 a tick. */
uint16_t step_period(uint32_t dist, uint16_t span)
{
    /* d = dist / 2^12, from its bytes (no 32-bit shift loops) */
    uint16_t hi = (uint16_t)(dist >> 16);
    if (hi >= 0x1000u)
        hi = 0x0FFFu; /* over 16 steps a tick: never at the advertised rate */
    uint16_t d = (uint16_t)(hi << 4) | (uint8_t)((uint8_t)(dist >> 8) >> 4);
    if (d < 1024)
        return 0;
    /* normalised: d 2^s in [2^15, 2^16), s = 0..5 */
    uint8_t s = 0;
    if (!(d & 0xC000u)) {
        d <<= 2;
        s = 2;
    }
    while (!(d & 0x8000u)) {
        d <<= 1;
        s++;
    }
    /* span 2^14 / (d 2^-s) = span 2^(6 + s) / m = span r 2^(s - 16), r = 2^22 / m:
     * the product's bytes 1..3 (a byte move) shifted right 8 - s more */
    uint32_t p = mul16x16(span, pgm_read_word(&recip_table[(uint8_t)(d >> 8) - 128]));
    __uint24 q = (__uint24)(p >> 8);
    for (uint8_t k = (uint8_t)(8 - s); k; k--)
        q >>= 1;
    return q >> 16 ? 0 : (uint16_t)q;
}

