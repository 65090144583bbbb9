/* First-order thermal model of a heater and its 100k NTC (beta 3950, 4.7k pull-up). */
#ifndef SIM_THERMAL_H
#define SIM_THERMAL_H

struct thermal {
    double tau, gain, ambient, temp;
    double t_last, on_since, on_time;
    int on, element_ok;
};

void thermal_init(struct thermal *th, double tau, double gain);
void thermal_switch(struct thermal *th, double t, int on);
void thermal_advance(struct thermal *th, double t);
unsigned thermal_millivolts(const struct thermal *th);

#endif
