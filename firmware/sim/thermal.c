#include <math.h>

#include "thermal.h"
#include "thermal_plant.h"

void thermal_init(struct thermal *th, int heater)
{
    th->tau = heater ? BED_TAU_S : HOTEND_TAU_S;
    th->gain = heater ? BED_GAIN_C : HOTEND_GAIN_C;
    th->ambient = heater ? BED_AMBIENT_C : HOTEND_AMBIENT_C;
    th->noise_c = heater ? BED_NOISE_C : HOTEND_NOISE_C;
    double dead = heater ? BED_DEAD_TIME_S : HOTEND_DEAD_TIME_S;
    th->delay_len = (int)(dead / THERMAL_BIN_S + 0.5);
    if (th->delay_len > THERMAL_DELAY_MAX)
        th->delay_len = THERMAL_DELAY_MAX;
    for (int i = 0; i < th->delay_len; i++)
        th->delay[i] = 0.0;
    th->delay_head = 0;
    th->decay = exp(-THERMAL_BIN_S / th->tau);
    th->temp = th->ambient;
    th->bin_end = THERMAL_BIN_S;
    th->bin_on = th->on_since = 0.0;
    th->noise = th->next_noise = 0.0;
    th->rng = heater ? 0x2545F491u : 0x9E3779B9u;
    th->on = 0.0;
    th->element_ok = 1;
    th->sensor = SENSOR_OK;
}

/* xorshift32, then Box-Muller: one normal deviate */
static double uniform(struct thermal *th)
{
    uint32_t x = th->rng;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    th->rng = x;
    return ((double)x + 1.0) / 4294967297.0;
}

static double gauss(struct thermal *th)
{
    double u = uniform(th), v = uniform(th);
    return sqrt(-2.0 * log(u)) * cos(6.283185307179586 * v);
}

void thermal_switch(struct thermal *th, double t, double power)
{
    if (power == th->on)
        return;
    thermal_advance(th, t);
    th->bin_on += (t - th->on_since) * th->on;
    th->on_since = t;
    th->on = power;
}

/* Close every bin that ended by t: its duty enters the delay line, and the duty that
 * left it (the power of one dead time ago) drives the temperature for one bin. */
void thermal_advance(struct thermal *th, double t)
{
    while (th->bin_end <= t) {
        double on = th->bin_on + (th->bin_end - th->on_since) * th->on;
        th->on_since = th->bin_end;
        th->bin_on = 0.0;
        double duty = on / THERMAL_BIN_S, arrived = duty;
        if (th->delay_len) {
            arrived = th->delay[th->delay_head];
            th->delay[th->delay_head] = duty;
            th->delay_head = (th->delay_head + 1) % th->delay_len;
        }
        double steady = th->ambient + (th->element_ok ? th->gain * arrived : 0.0);
        th->temp = steady + (th->temp - steady) * th->decay;
        th->bin_end += THERMAL_BIN_S;
    }
    if (t >= th->next_noise) {
        th->noise = th->noise_c * gauss(th);
        th->next_noise += THERMAL_NOISE_HOLD_S;
        if (th->next_noise <= t)
            th->next_noise = t + THERMAL_NOISE_HOLD_S;
    }
}

unsigned thermal_millivolts(const struct thermal *th)
{
    if (th->sensor == SENSOR_OPEN)
        return 5000; /* no current through the divider: the pull-up's full voltage */
    if (th->sensor == SENSOR_SHORT)
        return 0;
    double temp = th->temp + th->noise;
    double r = 100000.0 * exp(3950.0 * (1.0 / (temp + 273.15) - 1.0 / 298.15));
    return (unsigned)(5000.0 * r / (r + 4700.0) + 0.5);
}
