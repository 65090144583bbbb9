/* A 16 x 16 -> 32-bit unsigned product inline: the MCU's MUL four times (libgcc's
 * call costs more than the multiplies). */
#ifndef MUL16_H
#define MUL16_H
#include <stdint.h>

/* a b, 16 x 16 -> 32 bits, inline (libgcc's call costs more than the four multiplies) */
static inline __attribute__((always_inline)) uint32_t mul16x16(uint16_t a, uint16_t b)
{
    uint32_t r;
    __asm__("mul %A1, %A2\n\t"
            "movw %A0, r0\n\t"
            "mul %B1, %B2\n\t"
            "movw %C0, r0\n\t"
            "mul %A1, %B2\n\t"
            "add %B0, r0\n\t"
            "adc %C0, r1\n\t"
            "clr __zero_reg__\n\t"
            "adc %D0, __zero_reg__\n\t"
            "mul %B1, %A2\n\t"
            "add %B0, r0\n\t"
            "adc %C0, r1\n\t"
            "clr __zero_reg__\n\t"
            "adc %D0, __zero_reg__"
            : "=&r"(r)
            : "r"(a), "r"(b));
    return r;
}

/* a b, 8 x 8 -> 16 bits (one MUL; the compiler shifts instead) */
static inline __attribute__((always_inline)) uint16_t mul8x8(uint8_t a, uint8_t b)
{
    uint16_t r;
    __asm__("mul %1, %2\n\t"
            "movw %0, r0\n\t"
            "clr __zero_reg__"
            : "=r"(r)
            : "r"(a), "r"(b));
    return r;
}

#endif
