#include <avr/io.h>

#include "adc.h"

void adc_init(void)
{
    ADMUX = _BV(REFS0);                                   /* AVCC reference */
    ADCSRA = _BV(ADEN) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0); /* 125 kHz ADC clock */
    DIDR2 = 0x60;                                         /* ADC13, ADC14 digital inputs off */
}

void adc_start(uint8_t channel)
{
    ADMUX = (uint8_t)(_BV(REFS0) | (channel & 7));
    if (channel & 8)
        ADCSRB |= _BV(MUX5);
    else
        ADCSRB &= (uint8_t)~_BV(MUX5);
    ADCSRA |= _BV(ADSC);
}

uint8_t adc_ready(void)
{
    return !(ADCSRA & _BV(ADSC));
}

uint16_t adc_value(void)
{
    return ADC;
}
