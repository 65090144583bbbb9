/* Device state the protocol reports on, the session's settings, the fault state. */
#ifndef MACHINE_H
#define MACHINE_H
#include <stdint.h>
#include "queue.h"
#include "stepper.h"

struct machine {
    uint32_t items_received, segments_received;
    uint8_t fault, last_error, estopped;
    uint8_t latched;        /* a thermal fault: only a reset clears it */
    uint8_t host_minor;     /* min(HELLO minor, ours) */
    /* soft travel limits (SET_LIMITS, kept until reset) and the modules homed once
     * everything queued has run (a queued HOME counts) */
    uint8_t limits_set, tail_homed;
    int32_t limit_lo[3], limit_hi[3];
    int32_t home_at[3]; /* logical position HOME gives a module at its switch (physical 0) */
    /* heater lease (HEATER_LEASE): armed by the first lease of a session */
    uint8_t lease_armed;
    uint16_t lease_ms;
    uint32_t lease_at;
    uint8_t synced;
    uint16_t nonce;
    uint16_t overflow_rejects;
    /* session settings (CONFIGURE; defaults at every new session) */
    uint16_t watchdog_ms;
    uint32_t start_ticks, flow_ticks;
    uint32_t last_frame_at; /* link time of the last valid frame (host watchdog) */
    uint32_t flush_item;    /* FLUSH: items up to this number may start at once */
    int32_t tail_pos[4];    /* where everything queued will have left the axes */
    /* the queue's contents for the start rule and buffered_ticks, kept by the
     * main loop: additions when it queues, departures when it sees them */
    uint32_t queued_units; /* durations of the segments and dwells in the queue */
    uint8_t block_ends;    /* queued items that end a block */
    uint8_t accounted;     /* queue position up to which departures are counted */
};
extern struct machine machine;

uint8_t machine_flags(void);
/* The same from a progress read the caller already holds. */
uint8_t machine_flags_of(const struct stepper_progress *done);
uint8_t machine_free(void);
/* Queue items of frames acknowledged and not executed yet (RING's `held`). */
uint8_t machine_held_items(void);
#if STEP_ENGINE
/* The credit FLOW gives the host (PROTOCOL.md 6): machine_free; for a 3.1 host (which
 * does not count the ring itself, RING) less with the step engine when the ring of
 * chunks would not take that many items' blocks at the mix of blocks the queue holds now
 * (step_blocks.h). Only what the host is told: the frames it sent under an older credit
 * are taken against machine_free. */
uint8_t machine_credit(void);
#else
static inline uint8_t machine_credit(void)
{
    return machine_free();
}
#endif
/* Account for the items the interrupt completed (main loop). */
void machine_account(void);
/* An item was queued at head (before queue_head moves on). */
void machine_queued(const struct item *it);
/* Motion not yet executed when ``done`` was taken: the rest of the executing item and
 * the queue. A report takes its counts and this from one snapshot, so that a FLOW never
 * counts an item done while its motion is still buffered. */
uint32_t machine_buffered_of(const struct stepper_progress *done);
/* The one shutdown path: stop the steppers where they are (motors stay enabled
 * unless SD_MOTORS_OFF), flush the queue (flushed items count as done), drive the
 * heater and fan pins low when SD_HEATERS_OFF, record the cause (a thermal fault
 * latches: nothing replaces it until a reset) and report it, every time. */
#define SD_HEATERS_OFF 0x01
#define SD_MOTORS_OFF 0x02
void machine_shutdown(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis,
                      int32_t value, uint8_t how);
/* A fault, the narrow way to raise one: machine_shutdown with what the code implies.
 * Heaters off for thermal faults, the watchdog, e-stop, the heater lease and a
 * failed autotune (any fault cancels an autotune and switches its heater off). */
void machine_fail(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis, int32_t value);
/* E-stop or host watchdog: stop now, fail with `code`, keep what the flags say. */
void machine_stop(uint8_t code, uint8_t keep_heaters, uint8_t keep_motors, int32_t value);
/* THERMAL_RUNAWAY and OVERTEMP: latched until a reset. */
uint8_t machine_thermal(uint8_t code);
enum { CLEAR_NOTHING, CLEAR_DONE, CLEAR_REFUSED };
uint8_t machine_clear_fault(void);
/* ENDSTOP_HIT module (>= 0) and *pos when a segment ending at end[] leaves the soft
 * limits of a homed module; -1 when it stays inside. */
int8_t machine_limits_violation(const int32_t *end, int32_t *pos);
/* A new session: the settings go back to their defaults. */
void machine_session_defaults(void);

/* What the machine needs from the layers above it, registered by main.c (the machine
 * names neither the command layer nor the reports): the report of every fault, and
 * the queue items of acknowledged frames not queued yet (not free for the host). */
struct machine_upper {
    void (*on_fault)(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis,
                     int32_t value);
    uint8_t (*pending_items)(void);
};
void machine_attach(const struct machine_upper *upper);

#endif
