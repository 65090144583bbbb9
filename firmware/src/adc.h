/* Polled ADC conversions against AVCC, one channel after the other. */
#ifndef ADC_H
#define ADC_H
#include <stdint.h>
void adc_init(void);
void adc_start(uint8_t channel);
uint8_t adc_ready(void);
uint16_t adc_value(void);
#endif
