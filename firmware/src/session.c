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
#include "stepper.h"
#include "mailbox.h"

static uint32_t boot_sent_at;
static uint8_t boot_sent_once;
static uint8_t flow_valid;
static uint32_t flow_items;
static uint8_t flow_flags, flow_free;
static uint32_t flow_at;

void session_opened(void)
{
    flow_valid = 0;
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

uint8_t proto_flow(uint8_t *out)
{
    cli();
    flow_items = st.items_done;
    sei();
    flow_flags = machine_flags();
    flow_free = machine_free();
    flow_at = link_now;
    flow_valid = 1;
    return report_flow(out);
}

void proto_frame_seen(void)
{
    mc.last_frame_at = link_now;
}

/* PROTOCOL 5.1 "start from rest" (protocol 1): the queued segments up to the
 * first that ends at rest (or up to another item) are all there, or they add up
 * to DEV_START_BUFFER_MS, or the queue is full, or nothing arrived for
 * DEV_START_DELAY_MS. */
uint8_t session_may_start(uint32_t now)
{
    /* 0.25 s of real time worth of motion: device ticks scaled by the speed-up */
    uint16_t s = sim_mailbox.speedup_x16;
    uint32_t need = MS_TO_CLOCK(DEV_START_BUFFER_MS), total = 0;
    if (s > 16)
        need = need * s / 16;
    uint8_t tail = queue_tail, head = queue_head;
    if (tail == head)
        return 0;
    for (uint8_t i = tail; i != head; i++) {
        struct item *it = queue_slot(i);
        if (it->kind != IT_SEG)
            return 1;
        total += it->ticks;
        if ((it->flags & SEGF_AT_REST) || total >= need)
            return 1;
    }
    if (queue_free() == 0)
        return 1;
    return now - mc.last_enqueue_at >= MS_TO_CLOCK(DEV_START_DELAY_MS);
}

void session_poll(uint32_t now)
{
    if (!mc.synced) {
        if (!boot_sent_once || now - boot_sent_at >= MS_TO_CLOCK(DEV_BOOT_ANNOUNCE_MS))
            announce_boot(now);
        return;
    }
    cli();
    uint32_t items = st.items_done;
    sei();
    uint8_t flags = machine_flags();
    if (!flow_valid || items != flow_items || flags != flow_flags) {
        if (!flow_valid || machine_free() >= flow_free + QUEUE_SIZE / 8 ||
            now - flow_at >= MS_TO_CLOCK(DEV_FLOW_INTERVAL_MS))
            link_request_ack();
    }
    /* host watchdog: a silent host while the machine is busy */
    uint8_t busy = stepper_moving() || queue_used() || heaters[0].target_dc || heaters[1].target_dc;
    if (busy && !mc.fault && now - mc.last_frame_at >= MS_TO_CLOCK(HOST_WATCHDOG_MS)) {
        machine_fail(ERR_ESTOP, st.items_done, st.segments_done, 0xFE,
                     (int32_t)((now - mc.last_frame_at) / (CLOCK_HZ / 1000)));
        heater_all_off();
        stepper_disable_all();
    }
}
