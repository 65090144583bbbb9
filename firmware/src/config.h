/* Firmware parameters: what the device announces and how it behaves. */
#ifndef CONFIG_H
#define CONFIG_H

#include <stdint.h>

#define FIRMWARE_NAME "cdpr-avr"
#define FIRMWARE_VERSION "0.1.0"

#define BAUD 250000UL

/* Time. Segment and dwell durations, the device clock and every timer are in
 * units of the protocol clock: CLOCK_HZ (10 us), as in the Python device model,
 * so the host plans the same segments for both. The step interrupt runs on its
 * own grid of TICK_UNITS units (400 us, 2.5 kHz) and makes the last tick of each
 * timed item as long as it needs to be, so every segment and dwell lasts exactly
 * its duration; each step inside a tick is issued at its own time on the
 * segment's profile (stepper.c). Homing ticks are HOME_TICK_UNITS long: one
 * homing step each, 4000 steps/s. */
#define CLOCK_HZ 100000UL
#define UNIT_CYCLES (F_CPU / CLOCK_HZ)                  /* 160 */
#define TICK_UNITS 40
#define TICK_CYCLES (UNIT_CYCLES * TICK_UNITS)          /* 6400 */
#define HOME_TICK_UNITS 25
/* The step engine of issue 29 (step_engine.h), stage 1: a steady segment's steps from
 * one timer compare per edge, per stepper (1), instead of the tick's time wheel (0).
 * Built with 1 only for the measurements of stage 1 (firmware/tools/engine_rates.py)
 * until it holds the rates within the tolerance (firmware/README.md). */
#ifndef STEP_ENGINE
#define STEP_ENGINE 0
#endif

/* On the tick (without the step engine) every step costs the interrupts about 140 cycles
 * (placed, sorted, issued by its own compare B), a tick about 1,200 more, so the rate the firmware advertises is
 * what a print's mix (one module at the rate, the others slower and out of step) takes
 * with no tick overrun, also while it speeds up and slows down (an accelerating tick
 * places each step on its bent profile, which costs more) and the host's bytes arrive:
 * 8000 steps/s on any one axis. At 10000 a print's mix of ramps overran a tick at every
 * start from rest (the interrupt ran up to its whole 6,400 cycles), a few more when
 * the host's bytes came at the wrong moment, and now and then one tick was lost
 * outright: every later edge 400 us late (tests/firmware/test_step_timing.py). At
 * 8000: no overrun in 18 runs on a loaded machine, every edge within 9 us.
 * The host plans for 90 % of it. A build may set another (bench/firmware.py's rate search:
 * make BUILD=build/rate-N EXTRA_CFLAGS=-DMAX_STEP_RATE=NUL, N a multiple of 200). */
/* The step engine's build announces the same until it is the default: built with
 * -DMAX_STEP_RATE=26000UL (bench/print_on_avr.py --engine --rate 26000) it prints the cup
 * 0.4 % slower than with no cap and exactly as the Python device at the same limits, its
 * first layer and its resume after a reset are exact, but one cup under a loaded host
 * ended 14 steps off on module 1 (not traced yet), a stream that is mostly fast ramps
 * runs dry, and four axes in step at that rate are too many (firmware/README.md, the
 * step engine). */
#ifndef MAX_STEP_RATE
#define MAX_STEP_RATE 8000UL /* steps/s, any one axis */
#endif
/* STEPPING (protocol 3.1): the peak rate of an axis stepped from the segment's profile,
 * without a schedule block: on the tick's DDA and time wheel (a ramp the host sent without
 * its block, homing). Without the engine every axis is the tick's: MAX_STEP_RATE. With it,
 * the tick's 8,000 above (or less); the host sends a block for every faster ramp. */
#ifndef PROFILE_STEP_RATE
#if STEP_ENGINE
#define PROFILE_STEP_RATE (MAX_STEP_RATE < 8000UL ? MAX_STEP_RATE : 8000UL)
#else
#define PROFILE_STEP_RATE MAX_STEP_RATE
#endif
#endif
_Static_assert(PROFILE_STEP_RATE <= MAX_STEP_RATE, "the profile's stepping is the tick's");
/* STEP_BUDGET (protocol 3.3): the peak steps/s of the four axes summed (X, Y, Z modules
 * and the extruder); a segment over it is refused on receipt (STEP_RATE, axis 4). 0: no
 * budget beyond each axis's own MAX_STEP_RATE, and no test (motion.c).
 * Without the engine 0: the tick's rate is set by a print's mix already (above).
 * With it, each stepper's compare interrupts cost the CPU per edge, so what runs out with
 * several axes fast is the chip, not an axis: four steppers in step hold 22,000 each and
 * overrun their ticks from 24,000 (the four vectors then take 96 % of the CPU), three in
 * step with braking about 80,000 in all (docs/step-engine.md section 9): 80,000, at least
 * MAX_STEP_RATE (one axis alone always gets its own rate). A build announcing 100,000 or
 * more on one axis is a measurement build (firmware/tools/engine_rates.py and
 * bench/firmware_rates.py at 200,000: 3 x 33,000 + 3,300, four axes in step, to find
 * where the engine ends): 0, so it takes the streams it measures with; a measurement at
 * a lower MAX_STEP_RATE of more than 80,000 in all builds with -DTOTAL_STEP_RATE=0UL.
 * A multiple of 200 (motion.c's integer test). */
#ifndef TOTAL_STEP_RATE
#if STEP_ENGINE && MAX_STEP_RATE < 100000UL
#define TOTAL_STEP_RATE (MAX_STEP_RATE > 80000UL ? MAX_STEP_RATE : 80000UL)
#else
#define TOTAL_STEP_RATE 0UL
#endif
#endif
_Static_assert(TOTAL_STEP_RATE == 0 || TOTAL_STEP_RATE >= MAX_STEP_RATE,
               "the axes together take at least what one takes");

/* CAPS (protocol 2.1). The shortest segment: one whole tick, 400 us (a shorter one would
 * make the step interrupt's period shorter than its own run time; BAD_VALUE). The segment
 * rate sustained at 250000 baud on a clean line (bench/firmware.py's stream: 2000/s,
 * 0.5 ms segments, exact). A pulse later than the tolerance against its place in the
 * firmware's schedule counts as late (HEALTH). */
#define MIN_SEGMENT_TICKS TICK_UNITS
#define SEGMENT_RATE 2000UL
#define LATE_TOLERANCE_US 25

/* Step schedules (protocol 3.0, PROTOCOL.md 5.5), in cycles of CPU_HZ (IDENT cpu_hz):
 * a schedule block's edges lie within SCHEDULE_TOLERANCE_CYCLES of their ideal time
 * (1 us, docs/step-engine.md section 2), and none of its intervals is shorter than
 * MIN_STEP_INTERVAL_CYCLES: the period of MAX_STEP_RATE less what a schedule within its
 * tolerance may take off it (an edge early by the tolerance after one late by it, and
 * the rounding of both); a shorter one is BAD_VALUE. */
#define CPU_HZ F_CPU
#define SCHEDULE_TOLERANCE_CYCLES 16
#define MIN_STEP_INTERVAL_CYCLES (CPU_HZ / MAX_STEP_RATE - 2 * SCHEDULE_TOLERANCE_CYCLES - 1)

/* Move queue slots (a power of two, at most 128); 26 bytes each (queue.h). 64 with the
 * step engine: its ring of schedule chunks (step_blocks.h, 1,280 bytes) takes the rest. */
#ifndef QUEUE_SIZE
#define QUEUE_SIZE (STEP_ENGINE ? 64 : 128)
#endif
/* Segments prepared ahead of the step interrupt (DDA constants, 142 bytes each). */
#ifndef PLAN_SLOTS
/* 4 with the step engine: its steppers' state (about 160 bytes) would leave the stack
 * less than its margin otherwise (tools/stack_usage.py) */
#define PLAN_SLOTS (STEP_ENGINE ? 4 : 8)
#endif

/* Unacknowledged host payload bytes the device can hold (IDENT rx_window): the
 * host never has more in flight, so the UART's receive ring (uart.h) holds them
 * all even while the main loop is busy with a long frame. */
#define RX_WINDOW 192

/* Largest payload the host is asked to send (IDENT max_payload; the deframer takes
 * frames up to the protocol's 248): a frame is checked whole in one main-loop turn,
 * so its size bounds that turn (~20 segments, about 2 ms); framing costs 9 %. */
#define DEV_MAX_PAYLOAD 120

/* Fans: the part-cooling fan on D9. */
#define FAN_COUNT 1

/* Device-to-host report slots (window + backlog), bytes per report. */
#define REPORT_SLOTS 8
#define REPORT_MAX 114 /* STATUS and HEALTH in one payload: 91 + 23 at most (HEALTH's counters are 16-bit) */


/* Host watchdog: no valid frame for this long while a session is open and the
 * machine is busy (moving, heating) stops motion and switches the heaters off. */
#define HOST_WATCHDOG_MS 2000

/* Heaters */
#define HEATER_PERIOD_MS 100
#define HOTEND_MAX_DC 2850  /* 285.0 C: targets above 10x this are HEATER_RANGE */
#define BED_MAX_DC 1200
#define HOTEND_CUTOFF_DC 3000 /* OVERTEMP above this, whatever the target */
#define BED_CUTOFF_DC 1300
#define MINTEMP_DC 50         /* below 5.0 C with a target: sensor open (Marlin's MINTEMP) */
/* Thermal protection, Marlin's defaults (Configuration_adv.h): heating must rise
 * WATCH_MIN_RISE_DC within each watch period (WATCH_TEMP_PERIOD 40 s / WATCH_BED_TEMP_PERIOD
 * 60 s, WATCH_*_INCREASE 2 C); once the target was reached, a temperature more than the
 * hysteresis below it for the runaway period is a runaway (THERMAL_PROTECTION_PERIOD
 * 40 s / HYSTERESIS 4 C, the bed's 20 s / 2 C). The Python device model holds the same. */
#define HOTEND_WATCH_MS 40000UL
#define BED_WATCH_MS 60000UL
#define HOTEND_RUNAWAY_MS 40000UL
#define BED_RUNAWAY_MS 20000UL
#define HOTEND_HYSTERESIS_DC 40
#define BED_HYSTERESIS_DC 20
#define WATCH_MIN_RISE_DC 20
#define REACHED_BAND_DC 10
/* The heater duties the control loop sets expire after this many step ticks
 * (400 us each: 750 ticks, 0.3 s, three control periods) unless the loop refreshes them. */
#define HEATER_LEASE_TICKS (30000UL / TICK_UNITS)

#endif
