/* AUTOTUNE (PROTOCOL.md section 4): a relay autotune of one heater, Marlin's M303. */
#ifndef AUTOTUNE_H
#define AUTOTUNE_H
#include <stdint.h>

/* Main loop: start the tune of an AUTOTUNE item that began executing; at its end
 * apply and report the gains (EVENT AUTOTUNE_DONE) and let the queue go on, or
 * fail (ERROR AUTOTUNE_FAILED, heaters off). */
void autotune_poll(uint32_t now);
/* The heater a tune drives, or -1. */
int8_t autotune_heater(void);
/* Heater loop, every control period of the tuned heater: the relay's duty. */
uint8_t autotune_relay(int16_t temp_dc, uint32_t now);
/* The shutdown path: a tune never outlives its queue item (its heater goes off). */
void autotune_cancel(void);
/* How a tune ends, registered by main.c (the tune names neither the reports nor the
 * machine above it): EVENT AUTOTUNE_DONE, and the fault (machine_fail). */
struct autotune_upper {
    void (*event)(uint8_t code, uint32_t item, uint8_t n, const int32_t *values);
    void (*fail)(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis, int32_t value);
};
void autotune_attach(const struct autotune_upper *upper);

#endif
