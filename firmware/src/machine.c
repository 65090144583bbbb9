#include <avr/interrupt.h>

#include "autotune.h"
#include "heater.h"
#include "machine.h"
#include "sim_hooks.h"
#include "protocol_gen.h"
#include "queue.h"
#include "sched.h"
#include "stepper.h"
#include "step_blocks.h"

struct machine machine;
static const struct machine_upper *upper;

void machine_attach(const struct machine_upper *u)
{
    upper = u;
}

uint8_t machine_free(void)
{
    /* the items of a frame acknowledged but not yet executed are taken */
    return (uint8_t)(queue_free() - upper->pending_items());
}

uint8_t machine_held_items(void)
{
    return upper->pending_items();
}

#if STEP_ENGINE
/* entries of the ring the credit leaves for blocks larger than the queue's mix: half of
 * what a frame's blocks can take (a 3.1 host, which does not count the ring) */
#define CREDIT_SPARE (BLOCK_MOST / 2)
#define CREDIT_FLOOR 4
uint8_t machine_credit(void)
{
    /* a segment waits for room in the ring: none until it has it (the frames sent
     * meanwhile wait in the deframer, or are refused when it is full: sent again) */
    if (blocks_stalled)
        return 0;
    uint8_t free = machine_free();
    /* 3.2: the host counts the ring's entries itself (RING) and sends a block only when
     * it fits: the credit is the queue's again */
    if (machine.host_minor >= 2)
        return free;
    uint8_t used = blocks_used();
    uint8_t items = queue_used();
    if (!free || !used || !items)
        return free; /* (an empty queue's blocks end with the segment executing) */
    /* The queue's items hold `used` entries of the ring between them (its blocks still
     * held to their segments' ends too): the items of that mix the free entries take,
     * less the items acknowledged and not queued yet. The queue's room alone let the host
     * send up to a second of ramps, whose blocks take several times the ring's 128
     * entries: a segment then waited for room (in 15 % of the first layer's 20 ms
     * samples), its frame held, and the frames behind it were refused for the deframer's
     * room and sent again (about 1,600 refusals and 2,000 retransmissions a layer). */
    if (used >= BLOCK_CHUNKS - CREDIT_SPARE)
        return 0;
    /* the main loop asks every turn and the mix changes only as items come and go: the
     * division (about 200 cycles) again only then */
    static uint8_t mix_used, mix_items;
    static uint16_t mix_fit;
    if (used != mix_used || items != mix_items) {
        mix_used = used;
        mix_items = items;
        mix_fit = (uint16_t)((uint16_t)(BLOCK_CHUNKS - CREDIT_SPARE - used) * items / used);
    }
    uint16_t fit = mix_fit;
    /* the ring's blocks of items already out of the queue (prepared, executing, held to
     * their ends) count in `used` too, so with a short queue the mix reads too large: the
     * host was held back while the ring had room and the queue ran dry. While the ring is
     * at most half full, a few items go in any case */
    if (used <= BLOCK_CHUNKS / 2 && fit < CREDIT_FLOOR)
        fit = CREDIT_FLOOR;
    uint8_t pending = upper->pending_items();
    fit = fit > pending ? (uint16_t)(fit - pending) : 0;
    return fit < free ? (uint8_t)fit : free;
}
#endif

/* HOMED, ENABLED and WAITING from the interrupt's progress (in a frame of its own: the
 * snapshot is not on the stack under machine_flags' callers' deeper calls). */
uint8_t machine_flags_of(const struct stepper_progress *done)
{
    uint8_t f = 0;
    if ((done->homed_mask & 7) == 7)
        f |= FLAG_HOMED;
    if (done->enabled_mask)
        f |= FLAG_ENABLED;
    if (done->current == IT_WAIT || done->current == IT_TUNE)
        f |= FLAG_WAITING;
    if (stepper_moving())
        f |= FLAG_MOVING;
    if (machine.fault)
        f |= FLAG_FAULT;
    if (machine.estopped)
        f |= FLAG_ESTOP;
    if (heaters[0].target_dc || heaters[1].target_dc)
        f |= FLAG_HEATING;
    return f;
}

uint8_t machine_flags(void)
{
    struct stepper_progress done;
    stepper_progress(&done);
    return machine_flags_of(&done);
}

static uint8_t ends_block(const struct item *it)
{
    return it->kind != IT_SEG || (it->flags & SEGF_AT_REST);
}

static uint32_t duration(const struct item *it)
{
    return (it->kind == IT_SEG || it->kind == IT_DWELL) ? it->ticks : 0;
}

static void account_to(uint8_t tail)
{
    while (machine.accounted != tail) {
        const struct item *it = queue_slot(machine.accounted);
        machine.queued_units -= duration(it);
        machine.block_ends -= ends_block(it);
        machine.accounted++;
    }
}

void machine_account(void)
{
    account_to(queue_tail);
}

void machine_queued(const struct item *it)
{
    machine_account(); /* before the slot can have been reused */
    machine.queued_units += duration(it);
    machine.block_ends += ends_block(it);
}

uint32_t machine_buffered_of(const struct stepper_progress *done)
{
    account_to(done->tail);
    uint32_t executed = 0;
    uint32_t left = done->ticks_left;
    if (done->current == IT_SEG || done->current == IT_DWELL) {
        /* the executing item (at tail) is still counted whole */
        uint32_t d = duration(queue_slot(done->tail));
        uint32_t rest = left * TICK_UNITS;
        executed = rest < d ? d - rest : 0;
    }
    return machine.queued_units - executed;
}

uint8_t machine_thermal(uint8_t code)
{
    return code == ERR_THERMAL_RUNAWAY || code == ERR_OVERTEMP;
}

/* The one shutdown path (Klipper's shutdown): every fault that stops the machine
 * comes here. The heater (and fan) pins go low at once, written directly rather
 * than through the interrupt's PWM, so a stopped timer cannot keep them on; the
 * steppers stop where they are but stay enabled (a cable robot must not drop its
 * effector) unless SD_MOTORS_OFF; the cause is recorded (a thermal fault latches
 * until a reset: a later fault never replaces it) and every fault is reported, a
 * second one included. */
void machine_shutdown(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis,
                      int32_t value, uint8_t how)
{
    autotune_cancel(); /* an autotune never outlives its queue item */
    if (how & SD_HEATERS_OFF)
        heater_outputs_off();
    sim_last_error(code); /* before the abort marker names it */
    stepper_halt();
    machine.fault = code; /* the newest; a thermal one stays latched whatever follows */
    machine.last_error = code;
    if (machine_thermal(code))
        machine.latched = code;
    stepper_flush(machine.items_received, machine.segments_received);
    machine_account();
    stepper_positions(machine.tail_pos);
    if (how & SD_MOTORS_OFF)
        stepper_disable_all(); /* positions are no longer trustworthy */
    machine.tail_homed = stepper_homed_mask();
    upper->on_fault(code, item, segment, axis, value);
}

void machine_fail(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis, int32_t value)
{
    uint8_t off = machine_thermal(code) || code == ERR_ESTOP || code == ERR_WATCHDOG ||
                  code == ERR_HEATER_LEASE || code == ERR_AUTOTUNE_FAILED ||
                  code == ERR_STACK_OVERFLOW;
    machine_shutdown(code, item, segment, axis, value, off ? SD_HEATERS_OFF : 0);
}

void machine_stop(uint8_t code, uint8_t keep_heaters, uint8_t keep_motors, int32_t value)
{
    uint32_t items, segs;
    stepper_counts(&items, &segs);
    machine_shutdown(code, items, segs, 0xFF, value,
                     (uint8_t)((keep_heaters ? 0 : SD_HEATERS_OFF) |
                               (keep_motors ? 0 : SD_MOTORS_OFF)));
}

uint8_t machine_clear_fault(void)
{
    if (!machine.fault)
        return CLEAR_NOTHING;
    if (machine.latched)
        return CLEAR_REFUSED; /* latched until a reset, as Marlin and Klipper do */
    machine.fault = 0;
    machine.estopped = 0;
    stepper_resume();
    return CLEAR_DONE;
}

int8_t machine_limits_violation(const int32_t *end, int32_t *pos)
{
    uint8_t check = machine.limits_set & machine.tail_homed;
    /* every segment on receipt: a moving bit, not -Os's shift loop */
    for (uint8_t k = 0, bit = 1; check && k < 3; k++, bit <<= 1)
        if ((check & bit) && (end[k] < machine.limit_lo[k] || end[k] > machine.limit_hi[k])) {
            *pos = end[k];
            return (int8_t)k;
        }
    return -1;
}

void machine_session_defaults(void)
{
    machine.watchdog_ms = WATCHDOG_MS_DEFAULT;
    machine.lease_armed = 0;
    machine.start_ticks = MS_TO_CLOCK(DEV_START_MS);
    machine.flow_ticks = MS_TO_CLOCK(DEV_FLOW_MS);
}
