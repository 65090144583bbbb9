/* Session behaviour around the link (PROTOCOL.md 3, 5.4, 6): BOOT announcements,
 * unsolicited FLOW reports, the start rule and the host watchdog. */
#include <avr/interrupt.h>

#include "config.h"
#include "heater.h"
#include "link.h"
#include "machine.h"
#include "protocol_gen.h"
#include "queue.h"
#include "reports.h"
#include "sched.h"
#include "session.h"
#include "step_blocks.h"
#include "stepper.h"

static uint32_t boot_sent_at;
static uint8_t boot_sent_once;
/* what the last FLOW said, and when */
static uint8_t flow_valid;
static uint32_t flow_items, flow_motion, flow_at;
static uint8_t flow_flags, flow_free;
#if STEP_ENGINE
static uint8_t flow_tail, flow_ring_short; /* the ring's tail; it might hold the host back */

/* 3.2: the host sends a block only where the ring has room (RING); while a block of the
 * most a frame can carry would not fit, the host may be holding one back */
static uint8_t ring_short_for_host(void)
{
    return machine.host_minor >= 2 && !blocks_fit(BLOCK_MOST);
}
#endif

void session_opened(void)
{
    flow_valid = 0;
    machine_session_defaults();
    machine.last_frame_at = link_now;
}

static void announce_boot(uint32_t now)
{
    boot_sent_at = now;
    boot_sent_once = 1;
    report_boot();
}

void session_boot_on_data(void)
{
    uint32_t now = link_now;
    if (!boot_sent_once || now - boot_sent_at >= MS_TO_CLOCK(50))
        announce_boot(now);
}

/* The periodic announcement is not enough on its own: a host flushes its input when it
 * opens the port, and a flush that cuts a BOOT short leaves it bytes but no BOOT, on
 * which it sends HELLO at once; the session that HELLO opens ends the announcements, and
 * the record the boot kept (an exact resume's last executed segment) would never be
 * heard. So the first session's IDENT always comes after a whole BOOT. */
void session_boot_before_ident(void)
{
    announce_boot(link_now);
    link_flush_urgent(); /* out before the IDENT takes the urgent slot */
}

static uint32_t __attribute__((noinline)) motion_executed(void)
{
    struct stepper_progress done;
    stepper_progress(&done);
    return done.motion_ticks;
}

static uint32_t __attribute__((noinline)) items_executed(void)
{
    struct stepper_progress done;
    stepper_progress(&done);
    return done.items_done;
}

uint8_t proto_flow(uint8_t *out)
{
    flow_items = items_executed();
    flow_flags = machine_flags();
    flow_free = machine_credit();
    flow_motion = motion_executed();
    flow_at = link_now;
    flow_valid = 1;
#if STEP_ENGINE
    flow_tail = blocks_tail;
    flow_ring_short = ring_short_for_host();
#endif
    return report_flow(out);
}

void proto_frame_seen(void)
{
    machine.last_frame_at = link_now;
}

#if STEP_ENGINE
/* The host may send nothing more until the steppers free some of the ring of chunks:
 * FLOW's credit is 0 and every frame acknowledged is queued. A credit of 0 while
 * acknowledged frames still wait to be queued says only that the host waits for them
 * (a ramp's first pieces took it to 0 with 5 of them queued and 56 of the ring's 128
 * entries used: the motion started with 7.5 ms queued and ran dry). */
static uint8_t host_held_back(void)
{
    return !machine_credit() && machine_free() == queue_free();
}
#endif

/* PROTOCOL 5.4: at rest with a segment at the head of the queue, start when the
 * queue holds a whole block (an item that ends one), start_ticks of motion, a
 * full queue, or after FLUSH. O(1): the counts are kept as items come and go. */
uint8_t session_may_start(void)
{
    machine_account();
    if (queue_head == queue_tail)
        return 0;
    uint32_t head_item = items_executed() + 1;
    return machine.block_ends > 0 || machine.queued_units >= machine.start_ticks || queue_free() == 0 || blocks_stalled ||
#if STEP_ENGINE
           host_held_back() || ring_short_for_host() ||
#endif
           head_item <= machine.flush_item;
}

#if STEP_ENGINE
uint8_t session_start_for(void)
{
    uint8_t ok = session_may_start();
    uint8_t head = machine.accounted; /* queue_tail as session_may_start counted it */
    return ok ? head : (uint8_t)(head - 1);
}
#endif

/* An unsolicited FLOW: flow_ticks of motion executed, flags changed, an eighth of the
 * queue freed, or any other change after DEV_FLOW_INTERVAL_MS. Every turn asks: one
 * progress read for all of it (it was three), in a frame of its own (not on the stack
 * under session_poll's stops). */
static uint8_t __attribute__((noinline)) flow_due(uint32_t now)
{
    if (!flow_valid)
        return 1;
    struct stepper_progress done;
    stepper_progress(&done);
    if (machine.flow_ticks && done.motion_ticks - flow_motion >= machine.flow_ticks)
        return 1;
    uint8_t flags = machine_flags_of(&done);
    if (done.items_done == flow_items && flags == flow_flags)
        return 0;
    return flags != flow_flags || machine_credit() >= flow_free + QUEUE_SIZE / 8 ||
           now - flow_at >= MS_TO_CLOCK(DEV_FLOW_INTERVAL_MS);
}

/* Anything to do: motion executing or queued, a heater on (the watchdog guards it). */
static uint8_t active(void)
{
    return stepper_moving() || queue_used() || heaters[0].target_dc || heaters[1].target_dc;
}

void session_poll(uint32_t now)
{
    if (!machine.synced) {
        if (!boot_sent_once || now - boot_sent_at >= MS_TO_CLOCK(DEV_BOOT_ANNOUNCE_MS))
            announce_boot(now);
        return;
    }
    /* host watchdog, in every state (faulted included: a fault keeps a heater on for
     * the host to resume, and a host that dies after it must not leave it on): no
     * valid frame for watchdog_ms while there is something to do: stop, heaters off,
     * motors held (a cable robot would drop its effector) */
    if (active() &&
        now - machine.last_frame_at >= (uint32_t)machine.watchdog_ms * (CLOCK_HZ / 1000)) {
        machine_stop(ERR_WATCHDOG, 0, 1, machine.watchdog_ms);
        return;
    }
    /* heater lease (2.1): heater targets stand only while the host's job keeps renewing
     * them (a wedged host whose keep-alive thread still runs does not) */
    if (machine.lease_armed && (heaters[0].target_dc || heaters[1].target_dc) &&
        now - machine.lease_at >= MS_TO_CLOCK(machine.lease_ms)) {
        machine_stop(ERR_HEATER_LEASE, 0, 1, machine.lease_ms);
        return;
    }
    uint8_t want = flow_due(now);
#if STEP_ENGINE
    /* a credit the ring of chunks keeps short (machine_credit): each item more at once
     * (the ring frees as the steppers pass the segments' ends) */
    if (!want && flow_free < QUEUE_SIZE / 8 && machine_credit() > flow_free)
        want = 1;
    /* 3.2: a ring that may hold the host back reports each room the steppers free */
    if (!want && flow_ring_short && blocks_tail != flow_tail)
        want = 1;
#endif
    if (want)
        link_request_ack();
}
