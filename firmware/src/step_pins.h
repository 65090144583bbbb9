/* The stepper's pins on the RAMPS 1.4 (board_ramps14.h): step pulses, directions,
 * driver enables, the homing switches and the limit switches, as axis masks. */
#ifndef STEP_PINS_H
#define STEP_PINS_H

#include <avr/io.h>
#include <stdint.h>

#include "board_ramps14.h"
#include "config.h"

/* step pins of an axis mask on the X/Y port (the Z and E pins have ports of their own) */
static const uint8_t xy_bits[4] = {0, _BV(X_STEP_BIT), _BV(Y_STEP_BIT), _BV(X_STEP_BIT) | _BV(Y_STEP_BIT)};

static inline __attribute__((always_inline)) void pulse_on(uint8_t m)
{
    X_STEP_PORT |= xy_bits[m & 3];
    if (m & 4)
        Z_STEP_PORT |= _BV(Z_STEP_BIT);
    if (m & 8)
        E_STEP_PORT |= _BV(E_STEP_BIT);
}

/* End the tick's pulses of the axis mask m (raised by pulse_on(m)). Without the step
 * engine the tick drives every axis and lowers all four pins; with it, only its own: a
 * stepper's pin is the engine's, and lowering it would cut its pulse short or, when
 * another stepper's interrupt raised it early (its compare pending, RAISE_PENDING in
 * step_engine.c), make its own interrupt raise it a second time: a step too many. */
static inline __attribute__((always_inline)) void pulse_off(uint8_t m)
{
#if STEP_ENGINE
    X_STEP_PORT &= (uint8_t)~xy_bits[m & 3];
    if (m & 4)
        Z_STEP_PORT &= (uint8_t)~_BV(Z_STEP_BIT);
    if (m & 8)
        E_STEP_PORT &= (uint8_t)~_BV(E_STEP_BIT);
#else
    (void)m;
    X_STEP_PORT &= (uint8_t)~(_BV(X_STEP_BIT) | _BV(Y_STEP_BIT));
    Z_STEP_PORT &= (uint8_t)~_BV(Z_STEP_BIT);
    E_STEP_PORT &= (uint8_t)~_BV(E_STEP_BIT);
#endif
}

static inline void apply_enables(uint8_t mask)
{
    /* active low */
    if (mask & 1) X_EN_PORT &= (uint8_t)~_BV(X_EN_BIT); else X_EN_PORT |= _BV(X_EN_BIT);
    if (mask & 2) Y_EN_PORT &= (uint8_t)~_BV(Y_EN_BIT); else Y_EN_PORT |= _BV(Y_EN_BIT);
    if (mask & 4) Z_EN_PORT &= (uint8_t)~_BV(Z_EN_BIT); else Z_EN_PORT |= _BV(Z_EN_BIT);
    if (mask & 8) E_EN_PORT &= (uint8_t)~_BV(E_EN_BIT); else E_EN_PORT |= _BV(E_EN_BIT);
}

static inline void apply_dirs(uint8_t neg)
{
    if (((neg >> 0) & 1) ^ X_DIR_INVERT) X_DIR_PORT &= (uint8_t)~_BV(X_DIR_BIT); else X_DIR_PORT |= _BV(X_DIR_BIT);
    if (((neg >> 1) & 1) ^ Y_DIR_INVERT) Y_DIR_PORT &= (uint8_t)~_BV(Y_DIR_BIT); else Y_DIR_PORT |= _BV(Y_DIR_BIT);
    if (((neg >> 2) & 1) ^ Z_DIR_INVERT) Z_DIR_PORT &= (uint8_t)~_BV(Z_DIR_BIT); else Z_DIR_PORT |= _BV(Z_DIR_BIT);
    if (((neg >> 3) & 1) ^ E_DIR_INVERT) E_DIR_PORT &= (uint8_t)~_BV(E_DIR_BIT); else E_DIR_PORT |= _BV(E_DIR_BIT);
}

static inline uint8_t endstops_raw(void)
{
    uint8_t m = 0;
    if (((X_MIN_PIN >> X_MIN_BIT) & 1) == ENDSTOP_TRIGGERED_LEVEL)
        m |= 1;
    if (((Y_MIN_PIN >> Y_MIN_BIT) & 1) == ENDSTOP_TRIGGERED_LEVEL)
        m |= 2;
    if (((Z_MIN_PIN >> Z_MIN_BIT) & 1) == ENDSTOP_TRIGGERED_LEVEL)
        m |= 4;
    return m;
}

/* The homing switches as a module mask, debounced: a switch counts as pressed only when
 * four reads 10 us apart agree (30 us in all; Klipper samples an endstop 4 times 15 us
 * apart), so a burst of motor noise a few microseconds long does not end homing. Read
 * once per homing step (every HOME_TICKS ticks, only while homing): 480 busy cycles of
 * a 6400-cycle tick; the time homing takes is unchanged. */
#define ENDSTOP_SAMPLES 4
#define ENDSTOP_SAMPLE_CYCLES 160 /* 10 us at 16 MHz */
static inline uint8_t endstops(void)
{
    uint8_t m = endstops_raw();
    for (uint8_t i = 1; i < ENDSTOP_SAMPLES && m; i++) {
        __builtin_avr_delay_cycles(ENDSTOP_SAMPLE_CYCLES);
        m &= endstops_raw();
    }
    return m;
}

/* The limit switches at the end of travel, as a module mask. */
static inline uint8_t limits_pressed(void)
{
    uint8_t m = 0;
    if (((X_MAX_PIN >> X_MAX_BIT) & 1) == ENDSTOP_TRIGGERED_LEVEL)
        m |= 1;
    if (((Y_MAX_PIN >> Y_MAX_BIT) & 1) == ENDSTOP_TRIGGERED_LEVEL)
        m |= 2;
    if (((Z_MAX_PIN >> Z_MAX_BIT) & 1) == ENDSTOP_TRIGGERED_LEVEL)
        m |= 4;
    return m;
}

/* Assembly that raises the step pins of the axis mask in r24 (clobbers r24: the Z pin
 * is on PORTL, outside the bit-addressable ports), for the interrupts written in
 * assembly; its operands are STEP_PULSE_ASM_OPERANDS. */
#define STEP_PULSE_ASM(label)                                                              \
    "sbrc r24, 0\n\t"                                                                      \
    "sbi %[pf], %[xb]\n\t"                                                                 \
    "sbrc r24, 1\n\t"                                                                      \
    "sbi %[pf], %[yb]\n\t"                                                                 \
    "sbrc r24, 3\n\t"                                                                      \
    "sbi %[pa], %[eb]\n\t"                                                                 \
    "sbrs r24, 2\n\t"                                                                      \
    "rjmp " label "f\n\t"                                                                  \
    "lds r24, %[pl]\n\t"                                                                   \
    "ori r24, %[zm]\n\t"                                                                   \
    "sts %[pl], r24\n" label ":\n\t"
#define STEP_PULSE_ASM_OPERANDS                                                            \
    [pf] "I"(_SFR_IO_ADDR(PORTF)), [pa] "I"(_SFR_IO_ADDR(PORTA)),                          \
        [pl] "n"(_SFR_MEM_ADDR(PORTL)), [xb] "I"(X_STEP_BIT), [yb] "I"(Y_STEP_BIT),        \
        [eb] "I"(E_STEP_BIT), [zm] "M"(_BV(Z_STEP_BIT))

#endif
