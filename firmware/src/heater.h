/* Hotend and bed: thermistor readings, PID, thermal protection. */
#ifndef HEATER_H
#define HEATER_H
#include <stdint.h>

struct heater {
    int16_t temp_dc;
    uint16_t target_dc;
    uint8_t state;       /* HS_* */
    int16_t watch_temp;  /* temperature at the start of the watch period */
    uint32_t watch_at;   /* tick at which the watch period ends */
    uint32_t below_since;
    uint8_t below;
    float integ;
    int16_t last_dc;
    uint8_t reached_event; /* HEATER_REACHED to report */
    uint8_t fault;         /* ERR_* to report */
};
extern struct heater heaters[2];

void heater_init(void);
/* Run every few ms from the main loop: ADC conversions, control every HEATER_PERIOD_MS. */
void heater_poll(uint32_t now);
void heater_set_target(uint8_t id, uint16_t target_dc, uint32_t now);
/* Heaters and fan off at once, pins driven low directly (the shutdown path). */
void heater_outputs_off(void);
uint16_t heater_max_dc(uint8_t id);
/* SET_PID: gains x1000 in Marlin's units; all 0 = the defaults. */
void heater_set_pid(uint8_t id, uint32_t kp, uint32_t ki, uint32_t kd);
/* A controller that takes a heater over (AUTOTUNE's relay), registered by main.c: the
 * heater it drives (-1: none), and its duty every control period of that heater. */
struct heater_override {
    int8_t (*heater)(void);
    uint8_t (*duty)(int16_t temp_dc, uint32_t now);
};
void heater_attach_override(const struct heater_override *o);

#endif
