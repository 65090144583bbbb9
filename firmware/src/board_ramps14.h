/* RAMPS 1.4 on an Arduino Mega 2560: the whole pin map of this firmware.
 *
 * Axes 0..2 are the three slider modules (RAMPS X, Y, Z driver sockets), axis 3
 * is the extruder (E0 socket). Each signal is a port letter's registers and a bit.
 */
#ifndef BOARD_RAMPS14_H
#define BOARD_RAMPS14_H

#include <avr/io.h>

/* step / dir / enable (enable is active low on A4988, DRV8825, TMC2208) */
#define X_STEP_PORT PORTF /* A0 */
#define X_STEP_DDR DDRF
#define X_STEP_BIT 0
#define X_DIR_PORT PORTF /* A1 */
#define X_DIR_DDR DDRF
#define X_DIR_BIT 1
#define X_EN_PORT PORTD /* D38 */
#define X_EN_DDR DDRD
#define X_EN_BIT 7

#define Y_STEP_PORT PORTF /* A6 */
#define Y_STEP_DDR DDRF
#define Y_STEP_BIT 6
#define Y_DIR_PORT PORTF /* A7 */
#define Y_DIR_DDR DDRF
#define Y_DIR_BIT 7
#define Y_EN_PORT PORTF /* A2 */
#define Y_EN_DDR DDRF
#define Y_EN_BIT 2

#define Z_STEP_PORT PORTL /* D46 */
#define Z_STEP_DDR DDRL
#define Z_STEP_BIT 3
#define Z_DIR_PORT PORTL /* D48 */
#define Z_DIR_DDR DDRL
#define Z_DIR_BIT 1
#define Z_EN_PORT PORTK /* A8 */
#define Z_EN_DDR DDRK
#define Z_EN_BIT 0

#define E_STEP_PORT PORTA /* D26 */
#define E_STEP_DDR DDRA
#define E_STEP_BIT 4
#define E_DIR_PORT PORTA /* D28 */
#define E_DIR_DDR DDRA
#define E_DIR_BIT 6
#define E_EN_PORT PORTA /* D24 */
#define E_EN_DDR DDRA
#define E_EN_BIT 2

/* Direction polarity: DIR high moves an axis toward positive steps. Flip a
 * motor's direction in its wiring (swap one coil pair) or here. */
#define X_DIR_INVERT 0
#define Y_DIR_INVERT 0
#define Z_DIR_INVERT 0
#define E_DIR_INVERT 0

/* min endstops, inputs with pull-up; a normally-closed switch to GND reads high
 * when pressed (and when its wire breaks, which is the safe side) */
#define X_MIN_PIN PINE /* D3 */
#define X_MIN_PORT PORTE
#define X_MIN_DDR DDRE
#define X_MIN_BIT 5
#define Y_MIN_PIN PINJ /* D14 */
#define Y_MIN_PORT PORTJ
#define Y_MIN_DDR DDRJ
#define Y_MIN_BIT 1
#define Z_MIN_PIN PIND /* D18 */
#define Z_MIN_PORT PORTD
#define Z_MIN_DDR DDRD
#define Z_MIN_BIT 3
#define ENDSTOP_TRIGGERED_LEVEL 1
/* limit switches at the far end of each module's travel (RAMPS MAX sockets), wired and
 * read like the homing switches */
#define X_MAX_PIN PINE /* D2 */
#define X_MAX_PORT PORTE
#define X_MAX_DDR DDRE
#define X_MAX_BIT 4
#define Y_MAX_PIN PINJ /* D15 */
#define Y_MAX_PORT PORTJ
#define Y_MAX_DDR DDRJ
#define Y_MAX_BIT 0
#define Z_MAX_PIN PIND /* D19 */
#define Z_MAX_PORT PORTD
#define Z_MAX_DDR DDRD
#define Z_MAX_BIT 2

/* MOSFET outputs: high = on */
#define HOTEND_PORT PORTB /* D10 */
#define HOTEND_DDR DDRB
#define HOTEND_BIT 4
#define BED_PORT PORTH /* D8 */
#define BED_DDR DDRH
#define BED_BIT 5
#define FAN_PORT PORTH /* D9 */
#define FAN_DDR DDRH
#define FAN_BIT 6
/* ...and the timer output compares on those pins (pwm.c): D10 is OC2A, D9 OC2B (timer
 * 2, 8-bit), D8 OC4C (timer 4, 16-bit) */
#define HOTEND_PWM_OCR OCR2A
#define HOTEND_PWM_TCCR TCCR2A
#define HOTEND_PWM_COM _BV(COM2A1)
#define FAN_PWM_OCR OCR2B
#define FAN_PWM_TCCR TCCR2A
#define FAN_PWM_COM _BV(COM2B1)
#define BED_PWM_OCR OCR4C
#define BED_PWM_TCCR TCCR4A
#define BED_PWM_COM _BV(COM4C1)

/* thermistors: ADC channels (A13, A14), 4.7k pull-up to 5 V on the RAMPS */
#define HOTEND_ADC_CHANNEL 13
#define BED_ADC_CHANNEL 14
#define THERMISTOR_PULLUP_OHMS 4700

/* Marker outputs (the simulation harness builds its executed-segment record
 * from them and from the step/dir pins; on a board they only blink the LED).
 * MARK_EDGE is Timer1's compare C output (OC1C, D13, the board's LED): the
 * timer itself toggles it exactly at a tick boundary, whatever the interrupt's
 * latency, when a segment ends or motion (the ticks of segments, dwells,
 * homing) starts or stops there; the firmware leaves which of these it was in
 * RAM for the harness. Toggled by software at rest, on the servo header:
 * MARK_POS (D6) when positions were set (SET_POSITION, HOME), MARK_ABORT (D4)
 * just before the edge that ends an abandoned segment. */
#define MARK_EDGE_DDR DDRB /* D13, OC1C */
#define MARK_EDGE_BIT 7
#define MARK_POS_PIN PINH /* D6 */
#define MARK_POS_DDR DDRH
#define MARK_POS_BIT 3
#define MARK_ABORT_PIN PING /* D4 */
#define MARK_ABORT_DDR DDRG
#define MARK_ABORT_BIT 5

/* status LED (D13) */
#define LED_PORT PORTB
#define LED_DDR DDRB
#define LED_BIT 7

#endif
