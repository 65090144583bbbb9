/* The simulated heaters' plant (first order with dead time and heat loss, the numbers of
 * thermal_plant.h, generated from firmware_protocol/device/thermal_plant.py) and their
 * 100k NTC (beta 3950, 4.7k pull-up) with its noise. */
#ifndef SIM_THERMAL_H
#define SIM_THERMAL_H
#include <stdint.h>

#define THERMAL_BIN_S 0.01  /* the heater's power is averaged over bins this long */
#define THERMAL_DELAY_MAX 2048

enum { SENSOR_OK, SENSOR_OPEN, SENSOR_SHORT };

struct thermal {
    double tau, gain, ambient, temp, noise_c;
    double decay;               /* exp(-THERMAL_BIN_S / tau) */
    double bin_end, bin_on, on_since; /* bin_on: energy (power x s) of the bin so far */
    double delay[THERMAL_DELAY_MAX]; /* the bins' duties on their way to the thermistor */
    int delay_len, delay_head;
    double noise, next_noise;
    uint32_t rng;
    double on; /* power 0..1 since on_since */
    int element_ok, sensor;
};

/* heater 0: the hotend, 1: the bed */
void thermal_init(struct thermal *th, int heater);
/* the heater's power (0..1, a PWM duty) from time t */
void thermal_switch(struct thermal *th, double t, double power);
void thermal_advance(struct thermal *th, double t);
unsigned thermal_millivolts(const struct thermal *th);

#endif
