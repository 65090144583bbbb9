/* 100k NTC, beta 3950, 4.7k pull-up, 10-bit ADC: ADC reading to 0.1 C. */
#ifndef THERMISTOR_H
#define THERMISTOR_H
#include <stdint.h>
int16_t thermistor_dc(uint16_t adc);
#endif
