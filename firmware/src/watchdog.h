/* Hardware watchdog, reset cause, counters that survive a soft reset. */
#ifndef WATCHDOG_H
#define WATCHDOG_H
#include <stdint.h>

void watchdog_start(void);
/* Feed the hardware watchdog if the scheduler's clock moved since the last feed. */
void watchdog_kick(uint32_t clock);
uint8_t watchdog_boot_cause(void);  /* BOOT_* */
uint8_t watchdog_prev_valid(void);
/* Motors enabled before a watchdog or soft reset (0 after power-on): held again at boot. */
uint8_t watchdog_prev_enabled(void);
uint32_t watchdog_prev_items(void);
uint32_t watchdog_prev_segments(void);
uint32_t watchdog_boot_id(void);
/* The canary word at the end of static RAM is intact (the stack never reached it). */
uint8_t watchdog_canary_ok(void);
/* Bytes between the static data and the deepest the stack has reached so far. */
uint16_t watchdog_stack_free(void);
/* keep the counters where a watchdog reset finds them */
void watchdog_save(uint32_t items_done, uint32_t segments_done, uint8_t enabled_mask);

#endif
