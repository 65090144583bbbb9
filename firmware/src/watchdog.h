/* Hardware watchdog, reset cause, counters that survive a soft reset. */
#ifndef WATCHDOG_H
#define WATCHDOG_H
#include <stdint.h>

void watchdog_start(void);
void watchdog_kick(void);
uint8_t watchdog_boot_cause(void);  /* BOOT_* */
uint8_t watchdog_prev_valid(void);
uint32_t watchdog_prev_items(void);
uint32_t watchdog_prev_segments(void);
uint32_t watchdog_boot_id(void);
/* keep the counters where a watchdog reset finds them */
void watchdog_save(uint32_t items_done, uint32_t segments_done);

#endif
