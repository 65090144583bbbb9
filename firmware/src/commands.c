/* Protocol 1 command table: decode a host DATA payload and act on it, exactly
 * as firmware_protocol/device/firmware.py does. The payload is parsed twice:
 * first to check every field and count queue items (a payload that does not
 * parse is one BAD_COMMAND and nothing of it runs; one with more queue items
 * than free slots is left unacknowledged), then to execute. */
#include <avr/interrupt.h>
#include <string.h>

#include "heater.h"
#include "link.h"
#include "machine.h"
#include "mailbox.h"
#include "motion.h"
#include "protocol_gen.h"
#include "queue.h"
#include "reports.h"
#include "sched.h"
#include "segment.h"
#include "session.h"
#include "stepper.h"

static struct seg_ctx ctx;

void commands_reset_session(void)
{
    memset(&ctx, 0, sizeof ctx);
}

static const char *layout_of(uint8_t op)
{
    switch (op) {
#define X(code, name) \
    case code:        \
        return LAYOUT_##name;
        PROTO_OPCODE_TABLE(X)
#undef X
    }
    return 0;
}

static uint8_t queued_op(uint8_t op)
{
    switch (op) {
#define X(code, name) \
    case code:        \
        return QUEUED_##name;
        PROTO_OPCODE_TABLE(X)
#undef X
    }
    return 0;
}

/* Parse one non-segment message's fields into v[] (at most 8 numbers kept). */
static void parse_fields(struct reader *r, const char *layout, int32_t *v)
{
    uint8_t n = 0, mask = 0;
    for (const char *p = layout; *p && !r->err; p++) {
        switch (*p) {
        case 'b':
            mask = rd_u8(r);
            if (n < 8) v[n++] = mask;
            break;
        case 'u': {
            uint32_t u = rd_uv(r);
            if (n < 8) v[n++] = (int32_t)u; /* callers range-check as unsigned */
            break;
        }
        case 's':
            if (n < 8) v[n++] = rd_sv(r); else rd_sv(r);
            break;
        case 't':
            rd_text(r);
            break;
        case '4':
            for (uint8_t k = 0; k < 4; k++) {
                int32_t x = rd_sv(r);
                if (n < 8) v[n++] = x;
            }
            break;
        case 'm':
            for (uint8_t k = 0; k < 3; k++) {
                int32_t x = (mask >> k & 1) ? rd_sv(r) : 0;
                if (n < 8) v[n++] = x;
            }
            break;
        case 'E': {
            rd_u8(r);
            rd_uv(r);
            uint8_t cnt = rd_u8(r);
            for (uint8_t i = 0; i < cnt && !r->err; i++)
                rd_sv(r);
            break;
        }
        }
    }
}

static uint8_t check_payload(const uint8_t *payload, uint8_t len, struct seg_ctx *work,
                             uint8_t *queued)
{
    struct reader r = {payload, 0, len, 0};
    struct segment s;
    int32_t v[8];
    *queued = 0;
    while (r.pos < len && !r.err) {
        uint8_t op = payload[r.pos];
        if (op >= SEG_BASE) {
            segment_decode(&r, work, &s);
            (*queued)++;
            continue;
        }
        const char *layout = layout_of(op);
        if (!layout)
            return 0;
        r.pos++;
        parse_fields(&r, layout, v);
        *queued += queued_op(op);
    }
    return !r.err;
}

static struct item *new_item(uint8_t kind)
{
    struct item *it = queue_slot(queue_head);
    it->kind = kind;
    it->flags = 0;
    it->ticks = 0;
    return it;
}

static void push_item(void)
{
    stepper_start_ok = 0; /* the start rule is evaluated again with this item */
    cli();
    queue_head++;
    sei();
    mc.last_enqueue_at = link_now;
}

/* a queue item has been numbered; discard it while faulted */
static uint8_t discard_if_fault(void)
{
    if (!mc.fault)
        return 0;
    cli();
    st.items_done = mc.items_received;
    sei();
    return 1;
}

static void enqueue_segment(const struct segment *s)
{
    mc.items_received++;
    mc.segments_received++;
    sim_mailbox.segments_parsed++;
    if (discard_if_fault())
        return;
    uint32_t rate;
    int8_t axis = motion_rate_check(s, &rate);
    if (axis >= 0) {
        machine_fail(ERR_STEP_RATE, mc.items_received, mc.segments_received, (uint8_t)axis,
                     (int32_t)rate);
        return;
    }
    motion_store(new_item(IT_SEG), s);
    push_item();
}

static void enqueue_command(uint8_t op, const int32_t *v)
{
    mc.items_received++;
    uint32_t n = mc.items_received;
    if ((op == OP_SET_HEATER || op == OP_WAIT_HEATER) && v[0] > 1) {
        machine_fail(ERR_BAD_COMMAND, n, 0, (uint8_t)v[0], 0);
        return;
    }
    if (discard_if_fault())
        return;
    struct item *it;
    switch (op) {
    case OP_SET_POSITION:
        it = new_item(IT_SETPOS);
        for (uint8_t k = 0; k < 4; k++)
            it->u.pos[k] = v[k];
        break;
    case OP_ENABLE:
        it = new_item(IT_ENABLE);
        it->u.cmd.mask = (uint8_t)v[0];
        break;
    case OP_HOME:
        it = new_item(IT_HOME);
        it->flags = (uint8_t)(v[0] & 7);
        for (uint8_t k = 0; k < 3; k++)
            it->u.pos[k] = v[1 + k];
        break;
    case OP_DWELL:
        it = new_item(IT_DWELL);
        it->ticks = (uint32_t)v[0];
        break;
    case OP_SET_HEATER:
        if ((uint32_t)v[1] > heater_max_dc((uint8_t)v[0])) {
            machine_fail(ERR_HEATER_RANGE, n, 0, (uint8_t)v[0], v[1]);
            return;
        }
        it = new_item(IT_HEATER);
        it->u.cmd.id = (uint8_t)v[0];
        it->u.cmd.value = (uint16_t)v[1];
        break;
    case OP_SET_FAN:
        it = new_item(IT_FAN);
        it->u.cmd.id = (uint8_t)v[0];
        it->u.cmd.value = (uint16_t)v[1];
        break;
    default: /* OP_WAIT_HEATER */
        it = new_item(IT_WAIT);
        it->u.cmd.id = (uint8_t)v[0];
        it->u.cmd.value = (uint32_t)v[1] > 0xFFFF ? 0xFFFF : (uint16_t)v[1];
        break;
    }
    push_item();
}

uint8_t proto_accept(const uint8_t *payload, uint8_t len)
{
    if (!mc.synced) {
        session_boot_on_data();
        return 0;
    }
    struct seg_ctx work = ctx;
    uint8_t queued;
    if (!check_payload(payload, len, &work, &queued)) {
        machine_fail(ERR_BAD_COMMAND, mc.items_received, mc.segments_received, 0xFF, 0);
        return 1;
    }
    if (queued > machine_free() && !mc.fault) {
        mc.overflow_rejects++;
        return 0;
    }
    struct reader r = {payload, 0, len, 0};
    struct segment s;
    int32_t v[8];
    while (r.pos < len) {
        uint8_t op = payload[r.pos];
        if (op >= SEG_BASE) {
            segment_decode(&r, &ctx, &s);
            enqueue_segment(&s);
            motion_prepare_ahead(); /* keep the interrupt's plans coming during long frames */
            continue;
        }
        r.pos++;
        parse_fields(&r, layout_of(op), v);
        if (queued_op(op)) {
            enqueue_command(op, v);
        } else if (op == OP_GET_STATUS) {
            report_status();
        } else if (op == OP_IDENTIFY) {
            report_ident(mc.nonce, 0);
        } else if (op == OP_CLEAR_FAULT) {
            if (machine_clear_fault())
                report_event(EVT_FAULT_CLEARED, st.items_done, 0, 0);
        } else {
            machine_fail(ERR_BAD_COMMAND, mc.items_received, mc.segments_received, 0xFF, 0);
        }
    }
    ctx = work;
    return 1;
}

void proto_urgent(const uint8_t *payload, uint8_t len)
{
    struct seg_ctx scratch = {0, {0, 0, 0, 0}};
    uint8_t queued;
    if (!check_payload(payload, len, &scratch, &queued))
        return;
    struct reader r = {payload, 0, len, 0};
    struct segment s;
    int32_t v[8];
    while (r.pos < len) {
        uint8_t op = payload[r.pos];
        if (op >= SEG_BASE) {
            segment_decode(&r, &scratch, &s);
            continue;
        }
        r.pos++;
        parse_fields(&r, layout_of(op), v);
        if (op == OP_HELLO) {
            uint32_t nonce = (uint32_t)v[0];
            if (v[1] == PROTO_MAJOR && (!mc.synced || nonce != mc.nonce)) {
                link_reset_session();
                commands_reset_session();
                session_opened();
                mc.synced = 1;
                mc.nonce = nonce;
            }
            report_ident(nonce, 1);
        } else if (op == OP_EMERGENCY_STOP) {
            if (!mc.estopped)
                machine_estop();
            report_estop_ack();
        }
    }
}
