/* Firmware parameters: what the device announces and how it behaves. */
#ifndef CONFIG_H
#define CONFIG_H

#include <stdint.h>

#define FIRMWARE_NAME "cdpr-avr"
#define FIRMWARE_VERSION "0.1.0"

#define BAUD 250000UL

/* The step timer: one tick = one unit of segment and dwell durations (clock_hz). */
#define TICK_HZ 10000UL
#define TIMER_CYCLES_PER_TICK (F_CPU / TICK_HZ) /* 1600 */
/* Up to this many step pulses per axis per tick, at k/6 of the tick. */
#define MAX_STEPS_PER_TICK 6
#define MAX_STEP_RATE (TICK_HZ * MAX_STEPS_PER_TICK) /* 60000 steps/s, any one axis */

/* Move queue slots (power of two); see queue.h for the RAM per slot. */
#define QUEUE_SIZE 64

/* Device-to-host report slots (window + backlog), bytes per report. */
#define REPORT_SLOTS 8
#define REPORT_MAX 96


/* Host watchdog: no valid frame for this long while a session is open and the
 * machine is busy (moving, heating) stops motion and switches the heaters off. */
#define HOST_WATCHDOG_MS 2000

/* Heaters */
#define HEATER_PERIOD_MS 100
#define HOTEND_MAX_DC 2850  /* 285.0 C: targets above 10x this are HEATER_RANGE */
#define BED_MAX_DC 1200
#define HOTEND_CUTOFF_DC 3000 /* OVERTEMP above this, whatever the target */
#define BED_CUTOFF_DC 1300
#define MINTEMP_DC 50         /* below 5.0 C with a target: sensor open */
#define HOTEND_WATCH_MS 20000UL
#define BED_WATCH_MS 60000UL
#define HOTEND_HYSTERESIS_DC 150
#define BED_HYSTERESIS_DC 100
#define WATCH_MIN_RISE_DC 20
#define REACHED_BAND_DC 10

#endif
