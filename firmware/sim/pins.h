/* The harness's view of board_ramps14.h (port letters and bits). */
#ifndef SIM_PINS_H
#define SIM_PINS_H

struct pin { char port; int bit; };

static const struct pin STEP_PINS[4] = {{'F', 0}, {'F', 6}, {'L', 3}, {'A', 4}};
static const struct pin DIR_PINS[4] = {{'F', 1}, {'F', 7}, {'L', 1}, {'A', 6}};
static const struct pin ENDSTOP_PINS[3] = {{'E', 5}, {'J', 1}, {'D', 3}};
static const struct pin LIMIT_PINS[3] = {{'E', 4}, {'J', 0}, {'D', 2}}; /* MAX sockets */
static const struct pin EN_PINS[4] = {{'D', 7}, {'F', 2}, {'K', 0}, {'A', 2}}; /* active low */
/* the heaters' outputs (hotend D10 = OC2A, bed D8 = OC4C) as data-space addresses of
 * the ATmega2560's registers: the harness reads their PWM duty */
struct heater_pwm {
    unsigned tccr_a, tccr_b, ocr, com, port, ddr, bit;
};
static const struct heater_pwm HEATER_PWM[2] = {
    {0xB0, 0xB1, 0xB3, 0x80, 0x25, 0x24, 4},    /* TCCR2A, TCCR2B, OCR2A, COM2A1, PORTB, DDRB */
    {0xA0, 0xA1, 0xAC, 0x08, 0x102, 0x101, 5}, /* TCCR4A, TCCR4B, OCR4CL, COM4C1, PORTH, DDRH */
};
static const struct pin MARK_EDGE = {'B', 7}; /* OC1C */
static const struct pin MARK_POS = {'H', 3};
static const struct pin MARK_ABORT = {'G', 5};

#endif
