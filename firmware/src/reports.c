#include "config.h"
#include "frame.h"
#include "heater.h"
#include "link.h"
#include "machine.h"
#include "protocol_gen.h"
#include "pwm.h"
#include "queue.h"
#include "reports.h"
#include "stepper.h"
#include "step_blocks.h"
#include "watchdog.h"
#include "wire.h"
#include <avr/interrupt.h>

#include "sched.h"

static uint8_t buf[REPORT_MAX];
static void (*health_source)(struct health *out);

void reports_attach_health(void (*read)(struct health *out))
{
    health_source = read;
}

static struct writer start(uint8_t op)
{
    struct writer w = {buf, 0, sizeof buf, 0};
    wr_u8(&w, op);
    return w;
}

static void send(struct writer *w, uint8_t important)
{
    if (!w->err && machine.synced)
        link_send(buf, w->pos, important);
}

void report_error(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis, int32_t value)
{
    if (value < -SEG_MAX_DELTA)
        value = -SEG_MAX_DELTA; /* the range the Python model reports */
    struct writer w = start(CDPR_OP_ERROR);
    wr_u8(&w, code);
    wr_uv(&w, item);
    wr_uv(&w, segment);
    wr_u8(&w, axis);
    wr_sv(&w, value);
    send(&w, 1);
}

void report_event(uint8_t code, uint32_t item, uint8_t n, const int32_t *values)
{
    struct writer w = start(CDPR_OP_EVENT);
    wr_u8(&w, code);
    wr_uv(&w, item);
    wr_u8(&w, n); /* count, then the values */
    for (uint8_t i = 0; i < n; i++)
        wr_sv(&w, values[i]);
    send(&w, 0);
}

void report_status(void)
{
    int32_t pos[4];
    struct stepper_progress done;
    stepper_positions(pos);
    stepper_progress(&done);
    uint32_t buffered = machine_buffered_of(&done);
    uint32_t items = done.items_done, segs = done.segments_done, ticks = done.motion_ticks;
    uint8_t fan = pwm_fan(), en = done.enabled_mask, homed = done.homed_mask;
    struct writer w = start(CDPR_OP_STATUS);
    wr_u8(&w, (uint8_t)(machine_flags_of(&done) | (machine.synced ? FLAG_SYNCED : 0)));
    wr_uv(&w, machine_free());
    wr_uv(&w, machine.items_received);
    wr_uv(&w, items);
    wr_uv(&w, segs);
    wr_uv(&w, buffered);
    wr_uv(&w, ticks);
    wr_uv(&w, sched_clock());
    for (uint8_t k = 0; k < 4; k++)
        wr_sv(&w, pos[k]);
    wr_sv(&w, heaters[0].temp_dc);
    wr_uv(&w, heaters[0].target_dc);
    wr_sv(&w, heaters[1].temp_dc);
    wr_uv(&w, heaters[1].target_dc);
    wr_u8(&w, fan);
    wr_u8(&w, en);
    wr_u8(&w, homed);
    wr_u8(&w, machine.last_error);
    wr_uv(&w, deframer_stats.bad_frames + deframer_stats.bad_headers);
    wr_uv(&w, link_counters.retransmits);
    wr_uv(&w, link_counters.naks_sent);
    wr_uv(&w, link_counters.duplicates);
    { /* HEALTH right after STATUS, in the same payload (every 3.x session) */
        struct health hl;
        health_source(&hl);
        wr_u8(&w, CDPR_OP_HEALTH);
        wr_uv(&w, hl.late_pulses);
        wr_uv(&w, hl.late_worst_us);
        wr_uv(&w, hl.rx_overruns);
        wr_uv(&w, hl.loop_worst_us);
        wr_uv(&w, hl.lost_steps);
        wr_uv(&w, hl.tick_overruns);
        wr_uv(&w, hl.plan_stalls);
    }
    send(&w, 0);
}

void report_caps(void)
{
    struct writer w = start(CDPR_OP_CAPS);
    wr_uv(&w, MIN_SEGMENT_TICKS);
    wr_uv(&w, SEGMENT_RATE);
    wr_uv(&w, LATE_TOLERANCE_US);
    wr_uv(&w, SCHEDULE_TOLERANCE_CYCLES);
    wr_uv(&w, MIN_STEP_INTERVAL_CYCLES);
    send(&w, 0);
    if (machine.host_minor >= 1) { /* 3.1: what the tick steps without a block */
        struct writer s = start(CDPR_OP_STEPPING);
        wr_uv(&s, PROFILE_STEP_RATE);
        send(&s, 0);
    }
    if (TOTAL_STEP_RATE && machine.host_minor >= 3) { /* 3.3: the step rate the four axes
                                                         * share, from a build that has one */
        struct writer b = start(CDPR_OP_STEP_BUDGET);
        wr_uv(&b, TOTAL_STEP_RATE);
        send(&b, 0);
    }
}

void report_ident(uint16_t nonce, uint8_t urgent)
{
    uint32_t items, segs;
    stepper_counts(&items, &segs);
    struct writer w = start(CDPR_OP_IDENT);
    wr_uv(&w, nonce);
    wr_u8(&w, PROTO_MAJOR);
    wr_u8(&w, PROTO_MINOR);
    wr_uv(&w, watchdog_boot_id());
    wr_text(&w, FIRMWARE_NAME);
    wr_text(&w, FIRMWARE_VERSION);
    wr_u8(&w, AXES);
    wr_uv(&w, QUEUE_SIZE);
    wr_uv(&w, CLOCK_HZ);
    wr_uv(&w, CPU_HZ);
    wr_uv(&w, MAX_STEP_RATE);
    wr_u8(&w, DEV_MAX_PAYLOAD);
    wr_uv(&w, RX_WINDOW);
    wr_u8(&w, 2);         /* heaters */
    wr_u8(&w, FAN_COUNT); /* fans */
    wr_uv(&w, heater_max_dc(0));
    wr_uv(&w, heater_max_dc(1));
    wr_uv(&w, machine.watchdog_ms);
    wr_uv(&w, machine.start_ticks);
    wr_uv(&w, machine.items_received);
    wr_uv(&w, items);
    wr_uv(&w, machine.segments_received);
    wr_uv(&w, segs);
    wr_uv(&w, sched_clock());
    if (w.err)
        return;
    if (urgent)
        link_send_urgent(buf, w.pos);
    else
        send(&w, 0);
}

void report_boot(void)
{
    struct writer w = start(CDPR_OP_BOOT);
    wr_uv(&w, watchdog_boot_id());
    wr_u8(&w, watchdog_boot_cause());
    wr_u8(&w, PROTO_MAJOR);
    wr_u8(&w, PROTO_MINOR);
    wr_u8(&w, watchdog_prev_valid());
    wr_uv(&w, watchdog_prev_items());
    wr_uv(&w, watchdog_prev_segments());
    link_send_urgent(buf, w.pos);
}

void report_estop_ack(void)
{
    struct writer w = start(CDPR_OP_ESTOP_ACK);
    uint32_t items, segs;
    stepper_counts(&items, &segs);
    wr_uv(&w, items);
    wr_uv(&w, segs);
    link_send_urgent(buf, w.pos);
}

uint8_t report_flow(uint8_t *out)
{
    struct writer w = {out, 0, FLOW_MAX, 0};
    struct stepper_progress done; /* one snapshot: counts, flags and buffered agree */
    stepper_progress(&done);
    wr_u8(&w, CDPR_OP_FLOW);
    wr_u8(&w, machine_flags_of(&done));
    wr_uv(&w, machine_credit());
    wr_uv(&w, done.items_done);
    wr_uv(&w, done.segments_done);
    wr_uv(&w, machine_buffered_of(&done));
    wr_uv(&w, sched_clock());
#if STEP_ENGINE
    if (machine.host_minor >= 2) { /* 3.2: the ring of the schedule blocks' chunks */
        wr_u8(&w, CDPR_OP_RING);
        wr_u8(&w, BLOCK_CHUNKS);
        wr_u8(&w, blocks_head);
        wr_u8(&w, blocks_tail);
        wr_u8(&w, machine_held_items());
    }
#endif
    return w.pos;
}
