#include <avr/pgmspace.h>

#include "thermistor.h"
#include "thermistor_table.h"

int16_t thermistor_dc(uint16_t adc)
{
    /* the table is sorted by falling ADC value (rising temperature) */
    uint16_t a0 = pgm_read_word(&thermistor_table[0][0]);
    if (adc >= a0)
        return (int16_t)pgm_read_word(&thermistor_table[0][1]);
    for (uint8_t i = 1; i < THERMISTOR_TABLE_LEN; i++) {
        uint16_t a1 = pgm_read_word(&thermistor_table[i][0]);
        if (adc >= a1) {
            int16_t t0 = (int16_t)pgm_read_word(&thermistor_table[i - 1][1]);
            int16_t t1 = (int16_t)pgm_read_word(&thermistor_table[i][1]);
            return (int16_t)(t0 + (int32_t)(t1 - t0) * (int32_t)(a0 - adc) / (int32_t)(a0 - a1));
        }
        a0 = a1;
    }
    return (int16_t)pgm_read_word(&thermistor_table[THERMISTOR_TABLE_LEN - 1][1]);
}
