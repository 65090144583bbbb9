#include <avr/interrupt.h>
#include <avr/io.h>

#include "board_ramps14.h"
#include "pwm.h"

static volatile uint8_t fan_duty;

void pwm_init(void)
{
    HOTEND_PORT &= (uint8_t)~_BV(HOTEND_BIT);
    BED_PORT &= (uint8_t)~_BV(BED_BIT);
    FAN_PORT &= (uint8_t)~_BV(FAN_BIT);
    HOTEND_DDR |= _BV(HOTEND_BIT);
    BED_DDR |= _BV(BED_BIT);
    FAN_DDR |= _BV(FAN_BIT);
    OCR2A = 0;
    OCR2B = 0;
    OCR4C = 0;
    TCCR2A = _BV(WGM20); /* phase-correct, TOP 0xFF; compare outputs disconnected */
    TCCR2B = _BV(CS22);  /* F_CPU / 64 */
    TCCR4A = _BV(WGM40); /* phase-correct 8-bit */
    TCCR4B = _BV(CS42) | _BV(CS40); /* F_CPU / 1024 */
}

/* Connect the compare output `com` of `tccr` (duty > 0) or disconnect it (0). Timer 2's
 * control register holds the hotend's and the fan's outputs, changed from the main loop
 * and the step interrupt: masked for the read-modify-write, and only when it changes. */
static void connect(volatile uint8_t *tccr, uint8_t com, uint8_t duty)
{
    uint8_t want = duty ? com : 0;
    if ((*tccr & com) == want)
        return;
    uint8_t s = SREG;
    cli();
    *tccr = (uint8_t)((*tccr & (uint8_t)~com) | want);
    SREG = s;
}

void pwm_set_heater(uint8_t id, uint8_t duty)
{
    if (id) {
        BED_PWM_OCR = duty; /* timer 4's 16-bit registers: only ever written here */
        connect(&BED_PWM_TCCR, BED_PWM_COM, duty);
    } else {
        HOTEND_PWM_OCR = duty;
        connect(&HOTEND_PWM_TCCR, HOTEND_PWM_COM, duty);
    }
}

void pwm_set_fan(uint8_t duty)
{
    fan_duty = duty;
    FAN_PWM_OCR = duty;
    connect(&FAN_PWM_TCCR, FAN_PWM_COM, duty);
}

uint8_t pwm_fan(void)
{
    return fan_duty;
}

void pwm_heaters_off(void)
{
    uint8_t s = SREG;
    cli();
    HOTEND_PWM_TCCR &= (uint8_t)~HOTEND_PWM_COM;
    BED_PWM_TCCR &= (uint8_t)~BED_PWM_COM;
    HOTEND_PORT &= (uint8_t)~_BV(HOTEND_BIT);
    BED_PORT &= (uint8_t)~_BV(BED_BIT);
    SREG = s;
}

void pwm_all_off(void)
{
    uint8_t s = SREG;
    cli();
    pwm_heaters_off();
    FAN_PWM_TCCR &= (uint8_t)~FAN_PWM_COM;
    FAN_PORT &= (uint8_t)~_BV(FAN_BIT);
    fan_duty = 0;
    SREG = s;
}
