/* Device reports: encoders and where they go (link or URGENT). */
#ifndef REPORTS_H
#define REPORTS_H
#include <stdint.h>
#include "link.h" /* FLOW_MAX */
#include "protocol_gen.h"

void report_error(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis, int32_t value);
void report_event(uint8_t code, uint32_t item, uint8_t n, const int32_t *values);
void report_status(void);
void report_ident(uint16_t nonce, uint8_t urgent);
void report_boot(void);
void report_estop_ack(void);
void report_caps(void);
/* What HEALTH reports (2.1), gathered by the main loop. */
struct health {
    uint32_t late_pulses, late_worst_us, rx_overruns, loop_worst_us;
    uint32_t lost_steps, tick_overruns, plan_stalls;
};
/* The source of HEALTH's figures, registered by main.c (which gathers them). */
void reports_attach_health(void (*read)(struct health *out));
uint8_t report_flow(uint8_t *out); /* FLOW payload into out[FLOW_MAX] */

#endif
