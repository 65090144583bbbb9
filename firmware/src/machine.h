/* Device state the protocol reports on, and the fault state. */
#ifndef MACHINE_H
#define MACHINE_H
#include <stdint.h>

struct machine {
    uint32_t items_received, segments_received;
    uint8_t fault, last_error, estopped;
    uint8_t synced;
    uint32_t nonce;
    uint16_t overflow_rejects;
    uint32_t last_frame_at; /* tick of the last valid frame (host watchdog) */
    uint32_t last_enqueue_at;
};
extern struct machine mc;

uint8_t machine_flags(void);
uint8_t machine_free(void);
/* Enter the fault state: stop where it is, flush the queue (flushed items count
 * as done), heaters off for thermal faults and e-stop; report the error. */
void machine_fail(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis, int32_t value);
uint8_t machine_clear_fault(void);
void machine_estop(void);

#endif
