/* The move queue: items executed strictly in order by the step interrupt.
 * The main loop appends at head; the interrupt completes at tail. An item keeps
 * its slot while it executes (the protocol counts it as not free). */
#ifndef QUEUE_H
#define QUEUE_H
#include <stdint.h>
#include "config.h"

enum { IT_SEG, IT_DWELL, IT_HOME, IT_SETPOS, IT_ENABLE, IT_HEATER, IT_FAN, IT_WAIT };

#define SEGF_AT_REST 0x01 /* ends at rest (ramp 255 or no deltas) */

struct item {
    uint8_t kind;
    uint8_t flags; /* SEG: SEGF_*, dir bits in the high nibble (1 = negative) */
    uint32_t ticks;
    union {
        struct {
            int32_t v0[4]; /* Q8.24 steps per tick before the first tick's acceleration */
            int32_t a[4];  /* Q8.24 steps per tick per tick */
            uint32_t n[4]; /* |delta| */
        } seg;
        int32_t pos[4]; /* SETPOS positions, HOME targets */
        struct {
            uint8_t id, mask;
            uint16_t value;
        } cmd;
    } u;
};

extern struct item queue[QUEUE_SIZE];
extern volatile uint8_t queue_head, queue_tail;

static inline uint8_t queue_used(void)
{
    return (uint8_t)(queue_head - queue_tail);
}
static inline uint8_t queue_free(void)
{
    return (uint8_t)(QUEUE_SIZE - queue_used());
}
static inline struct item *queue_slot(uint8_t index)
{
    return &queue[index & (QUEUE_SIZE - 1)];
}

#endif
