/* The heater and fan MOSFET outputs, driven by the timers' output compares (no
 * interrupt spends a cycle on them):
 * - hotend (D10, OC2A) and fan (D9, OC2B): timer 2, phase-correct 8-bit PWM at F_CPU /
 *   64 / 510 = 490 Hz (the Arduino core's analogWrite rate on these pins, a RAMPS fan's
 *   usual one);
 * - bed (D8, OC4C): timer 4, phase-correct 8-bit PWM at F_CPU / 1024 / 510 = 30.6 Hz
 *   (the bed's MOSFET switches ~11 A: slow PWM keeps its switching losses small).
 * Phase-correct PWM holds 0 low and 255 high without a spike. A duty of 0 disconnects
 * the output at once (the pin's port bit, always 0, drives it low); any other takes
 * effect at the timer's next TOP (within 2 ms, or 33 ms for the bed). */
#ifndef PWM_H
#define PWM_H
#include <stdint.h>

/* Timers 2 and 4 running, every output low. */
void pwm_init(void);
/* heater 0: the hotend, 1: the bed; duty 0..255 */
void pwm_set_heater(uint8_t id, uint8_t duty);
void pwm_set_fan(uint8_t duty);
/* the fan's duty, as last set */
uint8_t pwm_fan(void);
/* Both heaters off now: their compare outputs disconnected and their pins driven low
 * directly, whatever the timers do. Any context. */
void pwm_heaters_off(void);
/* The heaters and the fan off now, the same way (the shutdown path). */
void pwm_all_off(void);

#endif
