#include <math.h>

#include "thermal.h"

void thermal_init(struct thermal *th, double tau, double gain)
{
    th->tau = tau;
    th->gain = gain;
    th->ambient = 25.0;
    th->temp = 25.0;
    th->t_last = th->on_since = th->on_time = 0.0;
    th->on = 0;
    th->element_ok = 1;
}

void thermal_switch(struct thermal *th, double t, int on)
{
    if (on == th->on)
        return;
    if (th->on)
        th->on_time += t - th->on_since;
    else
        th->on_since = t;
    th->on = on;
}

/* integrate since the last call with the mean power (duty) of that interval */
void thermal_advance(struct thermal *th, double t)
{
    double dt = t - th->t_last;
    if (dt <= 0)
        return;
    double on = th->on_time + (th->on ? t - th->on_since : 0.0);
    if (th->on)
        th->on_since = t;
    th->on_time = 0.0;
    double duty = on / dt;
    double steady = th->ambient + (th->element_ok ? th->gain * duty : 0.0);
    th->temp = steady + (th->temp - steady) * exp(-dt / th->tau);
    th->t_last = t;
}

unsigned thermal_millivolts(const struct thermal *th)
{
    double r = 100000.0 * exp(3950.0 * (1.0 / (th->temp + 273.15) - 1.0 / 298.15));
    return (unsigned)(5000.0 * r / (r + 4700.0) + 0.5);
}
