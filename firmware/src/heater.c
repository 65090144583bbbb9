/* Thermal protection in Marlin's manner (config.h: its default figures): while
 * heating, the temperature must rise WATCH_MIN_RISE_DC within each watch period
 * (else the heater or its thermistor has failed); once the target was reached, a
 * temperature more than the hysteresis below it for a whole runaway period is a
 * runaway. A reading
 * below MINTEMP_DC with a target set (open thermistor) or above the cut-off
 * (shorted thermistor, stuck MOSFET) is a fault whatever the target. */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "adc.h"
#include "board_ramps14.h"
#include "config.h"
#include "heater.h"
#include "lease.h"
#include "protocol_gen.h"
#include "pwm.h"
#include "sched.h"
#include "stepper.h"
#include "thermistor.h"

enum { HS_OFF, HS_HEATING, HS_REACHED };

struct heater heaters[2];
static uint8_t adc_busy, adc_which;
static uint32_t adc_sum[2];
static uint16_t adc_n[2];
static uint32_t next_control;

static const uint8_t channel[2] = {HOTEND_ADC_CHANNEL, BED_ADC_CHANNEL};
static const uint32_t watch_ticks[2] = {MS_TO_CLOCK(HOTEND_WATCH_MS), MS_TO_CLOCK(BED_WATCH_MS)};
static const uint32_t runaway_ticks[2] = {MS_TO_CLOCK(HOTEND_RUNAWAY_MS), MS_TO_CLOCK(BED_RUNAWAY_MS)};
static const int16_t hysteresis[2] = {HOTEND_HYSTERESIS_DC, BED_HYSTERESIS_DC};
static const int16_t cutoff[2] = {HOTEND_CUTOFF_DC, BED_CUTOFF_DC};
/* PID gains per 0.1 C, output 0..255, period HEATER_PERIOD_MS (defaults; SET_PID): what
 * a relay autotune finds on the simulated plant, hotend at 210 C (Marlin's units kp 10.8,
 * ki 0.80, kd 36.7) and bed at 60 C (71.7, 5.73, 224.4); the Python model's
 * default_gains are the same */
static const float kp0[2] = {1.08f, 7.17f};
static const float ki0[2] = {0.0080f, 0.0573f};
static const float kd0[2] = {36.7f, 224.4f};
static float kp[2] = {1.08f, 7.17f};
static float ki[2] = {0.0080f, 0.0573f};
static float kd[2] = {36.7f, 224.4f};

/* SET_PID gains x1000 in Marlin's units (output 0..255, error in C, time in s): per
 * 0.1 C and a 100 ms period, Kp / 10, Ki / 100 (the sum of errors times 0.1 s / 10)
 * and Kd (a change per period is d/dt x 0.1 s / 10). All 0: the defaults. */
void heater_set_pid(uint8_t id, uint32_t p, uint32_t i, uint32_t d)
{
    if (!p && !i && !d) {
        kp[id] = kp0[id];
        ki[id] = ki0[id];
        kd[id] = kd0[id];
    } else {
        kp[id] = (float)p * 1e-4f;
        ki[id] = (float)i * 1e-5f;
        kd[id] = (float)d * 1e-3f;
    }
    heaters[id].integ = 0;
}

uint16_t heater_max_dc(uint8_t id)
{
    return id ? BED_MAX_DC : HOTEND_MAX_DC;
}

void heater_init(void)
{
    pwm_init();
    adc_init();
    for (uint8_t i = 0; i < 2; i++)
        heaters[i].temp_dc = 250;
}

/* Heaters and fan off now: the compare outputs disconnected and the pins driven low
 * directly (whatever the timers and the lease do), no lease, the targets zero, a target
 * the interrupt executed but the main loop has not taken yet dropped. */
void heater_outputs_off(void)
{
    pwm_all_off();
    heater_lease_end();
    stepper_drop_heater_targets();
    for (uint8_t i = 0; i < 2; i++) {
        heaters[i].target_dc = 0;
        heaters[i].state = HS_OFF;
        heaters[i].integ = 0;
    }
}

void heater_set_target(uint8_t id, uint16_t target_dc, uint32_t now)
{
    struct heater *h = &heaters[id];
    h->target_dc = target_dc;
    h->integ = 0;
    h->below = 0;
    h->state = target_dc ? HS_HEATING : HS_OFF;
    h->watch_temp = h->temp_dc;
    h->watch_at = now + watch_ticks[id];
    if (!target_dc)
        pwm_set_heater(id, 0);
}

static void protect(uint8_t id, uint32_t now)
{
    struct heater *h = &heaters[id];
    if (h->temp_dc > cutoff[id]) {
        h->fault = ERR_OVERTEMP;
        return;
    }
    if (h->state == HS_OFF)
        return;
    if (h->temp_dc < MINTEMP_DC) {
        h->fault = ERR_THERMAL_RUNAWAY;
        return;
    }
    if (h->state == HS_HEATING) {
        if (h->temp_dc >= (int16_t)h->target_dc - REACHED_BAND_DC) {
            h->state = HS_REACHED;
            h->reached_event = 1;
        } else if ((int32_t)(now - h->watch_at) >= 0) {
            if (h->temp_dc < h->watch_temp + WATCH_MIN_RISE_DC) {
                h->fault = ERR_THERMAL_RUNAWAY;
                return;
            }
            h->watch_temp = h->temp_dc;
            h->watch_at = now + watch_ticks[id];
        }
    } else if (h->temp_dc < (int16_t)h->target_dc - hysteresis[id]) {
        if (!h->below) {
            h->below = 1;
            h->below_since = now;
        } else if (now - h->below_since >= runaway_ticks[id]) {
            h->fault = ERR_THERMAL_RUNAWAY;
        }
    } else {
        h->below = 0;
    }
}

static const struct heater_override *override;

void heater_attach_override(const struct heater_override *o)
{
    override = o;
}

static uint8_t pid(uint8_t id, uint32_t now)
{
    struct heater *h = &heaters[id];
    if (h->state == HS_OFF || h->fault)
        return 0;
    if (override->heater() == (int8_t)id)
        return override->duty(h->temp_dc, now); /* AUTOTUNE: the relay instead */
    float err = (float)h->target_dc - (float)h->temp_dc;
    float d = (float)(h->temp_dc - h->last_dc);
    if (err > 150.0f) {
        h->integ = 0;
        return 255;
    }
    if (err < -150.0f) {
        h->integ = 0;
        return 0;
    }
    float out = kp[id] * err + ki[id] * h->integ - kd[id] * d;
    if (out > 0.0f && out < 255.0f)
        h->integ += err; /* no wind-up while saturated */
    if (out < 0.0f)
        return 0;
    return out > 255.0f ? 255 : (uint8_t)out;
}

/* Every HEATER_PERIOD_MS: the temperatures from the samples taken since, the protection,
 * the duties. Out of line: its frame (the loop over the heaters, the PID's floats) cost
 * every main-loop turn's sample taking about 100 cycles. */
static void __attribute__((noinline)) heater_control(uint32_t now)
{
    next_control = now + MS_TO_CLOCK(HEATER_PERIOD_MS);
    uint8_t duty[2];
    for (uint8_t i = 0; i < 2; i++) {
        struct heater *h = &heaters[i];
        if (adc_n[i]) {
            h->last_dc = h->temp_dc;
            h->temp_dc = thermistor_dc((uint16_t)(adc_sum[i] / adc_n[i]));
            adc_sum[i] = 0;
            adc_n[i] = 0;
        }
        protect(i, now);
        duty[i] = pid(i, now);
    }
    /* the duties stand for HEATER_LEASE_TICKS step ticks: if this loop stops renewing
     * them, the step interrupt switches the heaters off by itself */
    heater_lease_grant(duty);
}

void heater_poll(uint32_t now)
{
    if (adc_busy) {
        if (!adc_ready())
            return;
        adc_sum[adc_which] += adc_value();
        adc_n[adc_which]++;
        adc_busy = 0;
        adc_which ^= 1;
    }
    adc_start(channel[adc_which]);
    adc_busy = 1;
    if ((int32_t)(now - next_control) >= 0)
        heater_control(now);
}
