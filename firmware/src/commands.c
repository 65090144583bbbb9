/* Host commands (PROTOCOL.md sections 4 and 8): decode a DATA or URGENT payload
 * with the field descriptors generated from the Python message table, check
 * every value, act. A DATA payload is parsed twice: first to check every field
 * and count queue items (a payload that does not decode is one BAD_COMMAND and
 * nothing of it runs; one with more queue items than free slots is left
 * unacknowledged), then to execute. A payload of segments only (a print's stream)
 * is decoded once instead, on receipt, into the queue slots its items will take
 * (stage_segments), and executed from there. */
#include <avr/interrupt.h>
#include <avr/pgmspace.h>
#include <stdint.h>
#include <string.h>

#include "frame.h"
#include "commands.h"
#include "heater.h"
#include "link.h"
#include "machine.h"
#include "sim_hooks.h"
#include "motion.h"
#include "protocol_gen.h"
#include "queue.h"
#include "reports.h"
#include "sched.h"
#include "segment.h"
#include "session.h"
#include "stepper.h"
#include "step_blocks.h"

struct field_desc {
    uint8_t type, count;
    int8_t mask;
    int32_t lo;
    uint32_t hi;
};

struct message_desc {
    uint8_t op, queued, urgent, nfields;
    const struct field_desc *fields;
};

#define MAX_VALUES 4
#define X(name)                                                                              \
    static const struct field_desc fields_##name[NFIELDS_##name ? NFIELDS_##name : 1] PROGMEM = \
        {FIELDS_##name};                                                                      \
    _Static_assert(NVALUES_##name <= MAX_VALUES, "values of " #name);
PROTO_HOST_MESSAGES(X)
#undef X

static const struct message_desc messages[] PROGMEM = {
#define X(name) {OP_##name, QUEUED_##name, URGENT_##name, NFIELDS_##name, fields_##name},
    PROTO_HOST_MESSAGES(X)
#undef X
};
#define N_MESSAGES (sizeof messages / sizeof messages[0])

static struct seg_ctx ctx;


static uint8_t find(uint8_t op, struct message_desc *out)
{
    for (uint8_t i = 0; i < N_MESSAGES; i++) {
        memcpy_P(out, &messages[i], sizeof *out);
        if (out->op == op)
            return 1;
    }
    return 0;
}

/* The fields of one message into v[] (signed fields as int32 bits); every value
 * checked against its type and fixed range. */
static void parse_fields(struct reader *r, const struct message_desc *m, uint32_t *v)
{
    uint8_t n = 0;
    for (uint8_t i = 0; i < m->nfields && !r->err; i++) {
        struct field_desc f;
        memcpy_P(&f, &m->fields[i], sizeof f);
        uint8_t mask = f.mask >= 0 ? (uint8_t)v[f.mask] : 0xFF;
        for (uint8_t k = 0; k < f.count && n < MAX_VALUES; k++, n++) {
            v[n] = 0;
            if (!(mask >> k & 1))
                continue;
            uint32_t raw = rd_field(r, f.type);
            if (f.type == FT_I16 || f.type == FT_I32) {
                int32_t x = unzigzag(raw);
                if (f.type == FT_I16 && (x < -32768L || x > 32767L))
                    r->err = 1;
                if (x < f.lo || x > (int32_t)f.hi)
                    r->err = 1;
                v[n] = (uint32_t)x;
            } else {
                if (raw < (uint32_t)f.lo || raw > f.hi) /* lo >= 0 for unsigned fields */
                    r->err = 1;
                v[n] = raw;
            }
        }
    }
}

/* Check a whole DATA payload; counts its queue items. Returns 0 with the
 * offending opcode and offset when it does not decode. */
static uint8_t check_payload(const uint8_t *payload, uint8_t len, struct seg_ctx *work,
                             uint8_t *queued, uint8_t *bad_op, uint8_t *bad_at, uint8_t *wrong)
{
    struct reader r = {payload, 0, len, 0};
    struct segment s;
    struct message_desc m;
    uint32_t v[MAX_VALUES];
    *queued = 0;
    *wrong = 0;
    segment_form_only = 1; /* the blocks' verdicts are taken as their segments are queued */
    while (r.pos < len) {
        motion_prepare_ahead(1); /* a frame of short segments takes milliseconds */
        uint8_t at = r.pos, op = payload[at];
        if (op >= SEG_BASE) {
            segment_decode(&r, work, &s);
            (*queued)++;
        } else if (find(op, &m)) {
            r.pos++;
            parse_fields(&r, &m, v);
            *queued += m.queued;
            if (m.urgent)
                *wrong = op; /* an URGENT-only message in a DATA frame */
        } else {
            r.err = 1;
        }
        if (r.err) {
            *bad_op = op;
            *bad_at = at;
            break;
        }
    }
    segment_form_only = 0;
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
    machine_queued(queue_slot(queue_head));
    cli();
    queue_head++;
    sei();
}

/* a queue item has been numbered; discard it while faulted (the queue is empty) */
static uint8_t discard_if_fault(void)
{
    if (!machine.fault)
        return 0;
    stepper_flush(machine.items_received, machine.segments_received);
    return 1;
}

static void bad_value(uint8_t op, int32_t value, uint32_t segment)
{
    machine_fail(ERR_BAD_VALUE, machine.items_received, segment, op, value);
}

/* A segment counted in order; 0 when a fault discards it */
static uint8_t count_segment(void)
{
    machine.items_received++;
    machine.segments_received++;
    sim_segment_parsed();
    return !discard_if_fault();
}

/* What a segment's own values allow (its duration and step rates against this
 * device's): 1, or 0 with the fault raised. */
static uint8_t segment_in_limits(const struct segment *s)
{
    if (s->ticks < MIN_SEGMENT_TICKS) { /* CAPS min_segment_ticks */
        bad_value(SEG_BASE, (int32_t)s->ticks, machine.segments_received);
        return 0;
    }
    uint32_t rate;
    int8_t axis = motion_rate_check(s, &rate);
    if (axis >= 0) {
        machine_fail(ERR_STEP_RATE, machine.items_received, machine.segments_received,
                     (uint8_t)axis, (int32_t)rate);
        return 0;
    }
    return 1;
}

/* move_tail's refusal, out of line: the fault (axis k's position out of 32 bits, or k 4:
 * a module out of its travel). The tail needs no undoing: the fault sets it to the
 * steppers' positions (machine_shutdown). */
static void __attribute__((noinline)) tail_refused(const struct item *it, uint8_t k)
{
    if (k == 4) {
        int32_t at;
        int8_t module = machine_limits_violation(machine.tail_pos, &at);
        /* refused on receipt: nothing of it moves */
        machine_fail(ERR_ENDSTOP_HIT, machine.items_received, machine.segments_received,
                     (uint8_t)module, at);
    } else {
        bad_value(SEG_BASE, (it->flags & (0x10 << k)) ? -SEG_MAX_DELTA : SEG_MAX_DELTA,
                  machine.segments_received);
    }
}

/* The checks that depend on where the queue's tail ends (the positions within 32 bits and
 * the modules' travel, at the time the segment is queued), for a stored segment: moves
 * machine.tail_pos by its steps axis by axis and returns 4 when all is well, k < 4 when
 * axis k would leave 32 bits (axes 0..k-1 moved), 5 when the moved tail leaves a module's
 * travel. In place, inline in move_tail and tails_moved (a copy of the four positions and
 * a frame of its own cost more than the checks). */
static inline __attribute__((always_inline)) uint8_t tail_steps(const struct item *it)
{
    int32_t *tail = machine.tail_pos;
    const uint32_t *np = it->u.n;
    uint8_t neg = it->flags >> 4, k = 0; /* bit k: axis k steps backwards */
    for (; k < 4; k++, neg >>= 1, tail++, np++) {
        /* |delta| <= 2^31 - 1 (the decoder's bound), so a sum leaves 32 bits only from
         * >= 0 to < 0, a difference only from < 0 to >= 0, and -2^31 is refused too:
         * sign tests in 32-bit arithmetic (no 64-bit library calls) */
        uint32_t t = (uint32_t)*tail, p;
        if (neg & 1) {
            p = t - *np;
            if ((int32_t)t < 0 && ((int32_t)p >= 0 || p == 0x80000000UL))
                break;
        } else {
            p = t + *np;
            if ((int32_t)t >= 0 && (int32_t)p < 0)
                break;
        }
        *tail = (int32_t)p;
    }
    if (k == 4) {
        int32_t at;
        if (machine_limits_violation(machine.tail_pos, &at) >= 0)
            return 5; /* (moved: a module out of its travel) */
    }
    return k;
}

/* tail_steps for the segment stored at queue_head: 1 with the tail moved, or 0 with the
 * fault raised (the tail left where its bad axis stopped it, as before a fault) */
static inline __attribute__((always_inline)) uint8_t move_tail(void)
{
    const struct item *it = queue_slot(queue_head);
    uint8_t k = tail_steps(it);
    if (k == 4)
        return 1;
    tail_refused(it, k == 5 ? 4 : k);
    return 0;
}

/* machine.tail_pos moved back by the first `axes` axes of a segment stored at a slot
 * (tail_steps moved them): a frame queued as it is checked, refused at a later segment */
static void __attribute__((noinline)) tail_back(const struct item *it, uint8_t axes)
{
    for (uint8_t k = 0, bit = 0x10; k < axes; k++, bit <<= 1)
        machine.tail_pos[k] += (it->flags & bit) ? (int32_t)it->u.n[k] : -(int32_t)it->u.n[k];
}

/* A segment in order: checked against this device's limits, stored, pushed. */
static void enqueue_segment(const struct segment *s)
{
    if (!count_segment())
        return;
    if (!segment_in_limits(s))
        return;
    if (s->sched.mask && s->sched.axis >= 0) { /* its schedule block, read with it */
        machine_fail(ERR_BAD_VALUE, machine.items_received, machine.segments_received,
                     (uint8_t)s->sched.axis, s->sched.value);
        return;
    }
    /* stored first (nothing reads the slot at queue_head before it is pushed; no frame
     * is staged behind one executed this way) */
    motion_store(new_item(IT_SEG), s);
    if (move_tail())
        push_item();
}

/* The staged segment at queue_head (stage_segments stored it, its own limits checked):
 * counted, its tail's checks, pushed. */
static void enqueue_staged(void)
{
    if (count_segment() && move_tail())
        push_item();
}

static void enqueue_command(uint8_t op, const uint32_t *v)
{
    machine.items_received++;
    struct item *it;
    /* ranges that depend on this device (PROTOCOL.md section 8) */
    switch (op) {
    case OP_DWELL:
        if (v[0] > (uint32_t)DWELL_MAX_S * CLOCK_HZ) {
            bad_value(op, v[0] > 0x7FFFFFFFUL ? 0x7FFFFFFFL : (int32_t)v[0], 0);
            return;
        }
        break;
    case OP_SET_HEATER:
    case OP_WAIT_HEATER:
    case OP_AUTOTUNE:
        if (v[0] > 1) {
            bad_value(op, (int32_t)v[0], 0);
            return;
        }
        break;
    case OP_SET_FAN:
        if (v[0] >= FAN_COUNT) {
            bad_value(op, (int32_t)v[0], 0);
            return;
        }
        break;
    }
    if (discard_if_fault())
        return;
    switch (op) {
    case OP_SET_POSITION:
        it = new_item(IT_SETPOS);
        for (uint8_t k = 0; k < 4; k++)
            machine.tail_pos[k] = it->u.pos[k] = (int32_t)v[k];
        break;
    case OP_ENABLE:
        it = new_item(IT_ENABLE);
        it->u.cmd.mask = (uint8_t)v[0];
        break;
    case OP_HOME:
        it = new_item(IT_HOME);
        it->flags = (uint8_t)(v[0] & 7);
        for (uint8_t k = 0; k < 3; k++) {
            it->u.pos[k] = (int32_t)v[1 + k];
            if (v[0] >> k & 1)
                machine.tail_pos[k] = machine.home_at[k] = (int32_t)v[1 + k];
        }
        machine.tail_homed |= (uint8_t)(v[0] & 7);
        break;
    case OP_DWELL:
        it = new_item(IT_DWELL);
        it->ticks = v[0];
        break;
    case OP_SET_HEATER:
        if (v[1] > heater_max_dc((uint8_t)v[0])) {
            machine_fail(ERR_HEATER_RANGE, machine.items_received, 0, (uint8_t)v[0], (int32_t)v[1]);
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
    case OP_AUTOTUNE:
        if (v[1] > heater_max_dc((uint8_t)v[0])) {
            machine_fail(ERR_HEATER_RANGE, machine.items_received, 0, (uint8_t)v[0], (int32_t)v[1]);
            return;
        }
        it = new_item(IT_TUNE);
        it->u.tune.id = (uint8_t)v[0];
        it->u.tune.target = (uint16_t)v[1];
        it->u.tune.cycles = (uint8_t)v[2];
        break;
    default: /* OP_WAIT_HEATER */
        it = new_item(IT_WAIT);
        it->u.cmd.id = (uint8_t)v[0];
        it->u.cmd.value = (uint16_t)v[1];
        break;
    }
    (void)it;
    push_item();
}

static void immediate(uint8_t op, const uint32_t *v)
{
    switch (op) {
    case OP_GET_STATUS:
        report_status();
        break;
    case OP_IDENTIFY:
        report_ident(0, 0);
        break;
    case OP_CLEAR_FAULT: {
        uint32_t items, segs;
        uint8_t done = machine_clear_fault();
        stepper_counts(&items, &segs);
        if (done == CLEAR_DONE) {
            report_event(EVT_FAULT_CLEARED, items, 0, 0);
        } else if (done == CLEAR_REFUSED) { /* a thermal fault: only a reset leaves it */
            int32_t code = machine.latched;
            report_event(EVT_CLEAR_REFUSED, items, 1, &code);
        }
        break;
    }
    case OP_SET_LIMITS:
        if ((int32_t)v[1] > (int32_t)v[2]) {
            bad_value(op, (int32_t)v[0], 0);
            break;
        }
        machine.limit_lo[v[0]] = (int32_t)v[1];
        machine.limit_hi[v[0]] = (int32_t)v[2];
        machine.limits_set |= (uint8_t)(1 << v[0]);
        break;
    case OP_SET_PID:
        heater_set_pid((uint8_t)v[0], v[1], v[2], v[3]);
        break;
    case OP_HEATER_LEASE:
        machine.lease_ms = (uint16_t)v[0];
        machine.lease_at = link_now;
        machine.lease_armed = 1;
        break;
    case OP_GET_CAPS:
        report_caps();
        break;
    case OP_FLUSH:
        machine.flush_item = machine.items_received;
        break;
    case OP_CONFIGURE:
        machine.watchdog_ms = (uint16_t)v[0];
        machine.start_ticks = v[1];
        machine.flow_ticks = v[2];
        break;
    }
}

/* Frames checked and acknowledged but not executed yet: their bytes wait in the
 * deframer (deframer_first / deframer_pop), their queue item counts here; they are
 * executed in order, a few messages per main-loop turn. `check` is the coder context
 * after the last checked frame, `ctx` the one after the last executed message. */
#define HELD_FRAMES 32
static struct {
    struct seg_ctx check;
    uint8_t items[HELD_FRAMES]; /* queue items of each held frame not queued yet */
    uint8_t head, n;
    uint16_t items_total;
    struct reader r; /* the frame being executed */
    uint8_t active;
    /* how many of the held frames, from the oldest, are staged (stage_segments): their
     * segments decoded once, into the queue slots they will take */
    uint8_t staged;
#if STEP_ENGINE
    /* the entries the block of the segment being executed takes, once known (0: not) */
    uint8_t block_need;
#endif
} pend;

void commands_reset_session(void)
{
    memset(&ctx, 0, sizeof ctx);
    memset(&pend, 0, sizeof pend);
    deframer_drop_held();
#if STEP_ENGINE
    blocks_stalled = 0; /* the segment that waited for the ring's room is forgotten */
#endif
}

uint8_t proto_pending_items(void)
{
    return (uint8_t)pend.items_total;
}

/* The tail's checks for the n segments stored from slot `at` (a frame queued as it is
 * checked): machine.tail_pos moved segment by segment, 1 when all are within 32 bits and
 * the travel; else 0 with the tail moved back to where it was (the checked way then
 * raises the fault at its segment). Out of the staging loop, once a frame: inline there,
 * its registers cost every segment's decode a frame of their own. */
static uint8_t __attribute__((noinline)) tails_moved(uint8_t at, uint8_t n)
{
    for (uint8_t i = 0; i < n; i++) {
        const struct item *it = queue_slot((uint8_t)(at + i));
        uint8_t k = tail_steps(it);
        if (k != 4) {
            tail_back(it, k < 4 ? k : 4);
            while (i)
                tail_back(queue_slot((uint8_t)(at + --i)), 4);
            return 0;
        }
    }
    return 1;
}

/* A frame of segments only (no schedule block) behind staged frames only, no fault:
 * decoded once, here, each segment stored (motion_store) straight into the queue slot
 * its item will take: queue_head + the held items before it. Nothing reads a slot
 * beyond queue_head before it is pushed, and the items are pushed in order, so when the
 * frame is executed its next item is always the one at queue_head (a fault discards
 * the rest unread). At 2,000 segments/s the second decode and the checked frame's walk
 * cost about a sixth of the CPU. Behind nothing held (the common case) the tail's checks
 * are made here too, machine.tail_pos moved segment by segment and moved back should one
 * fail, and the whole frame is queued at once (STAGE_QUEUED: nothing held). STAGE_NO
 * when the frame does not qualify, does not decode, does not fit or leaves the travel:
 * the checked way (check_payload) then decides, from the start, as before. */
enum { STAGE_NO, STAGE_HELD, STAGE_QUEUED };
static uint8_t stage_segments(const uint8_t *payload, uint8_t len, struct seg_ctx *work,
                              uint8_t *queued)
{
    if (pend.staged != pend.n || machine.fault)
        return STAGE_NO;
    /* nothing held before it: its tail's checks too, and queued at once (below) */
    uint8_t direct = !pend.n;
    struct reader r = {payload, 0, len, 0};
    struct segment s;
    /* the slots it may write reach back to the oldest completed item's: its departure is
     * counted first (machine_account reads the slot), and the room ends there, not at
     * queue_tail (an item completing meanwhile keeps its slot until it is counted) */
    machine_account();
    int16_t free = (int16_t)QUEUE_SIZE - (uint8_t)(queue_head - machine.accounted) -
                   (int16_t)pend.items_total;
    uint8_t room = free > 0 ? (uint8_t)free : 0, n = 0;
    uint8_t at = (uint8_t)(queue_head + pend.items_total);
    while (r.pos < len) {
        motion_prepare_ahead(1); /* a frame of short segments takes milliseconds */
        uint8_t op = payload[r.pos];
        if (op < SEG_BASE || (op & SEG_F_SCHEDULE) || n == room)
            return STAGE_NO;
        segment_decode(&r, work, &s);
        /* its own limits checked here (one over sends the frame the checked way, which
         * raises the fault at its segment); its tail's checks wait for its turn
         * (enqueue_staged) unless it goes to the queue at once */
        struct item *it = queue_slot((uint8_t)(at + n));
        if (r.err || s.ticks < MIN_SEGMENT_TICKS || !motion_store_checked(it, &s))
            return STAGE_NO;
        n++;
    }
    if (direct) {
        if (!tails_moved(at, n))
            return STAGE_NO;
        /* A frame of segments behind nothing held: checked whole and queued now, without
         * being held for proto_execute (at 2,000 segments/s its execution took a quarter
         * of the work a segment costs the main loop and left the segments out of the
         * queue for 3 ms after their check) */
        machine.items_received += n;
        machine.segments_received += n;
        for (uint8_t i = 0; i < n; i++) {
            sim_segment_parsed();
            machine_queued(queue_slot((uint8_t)(at + i)));
        }
        cli();
        queue_head = (uint8_t)(queue_head + n);
        sei();
        return STAGE_QUEUED;
    }
    *queued = n;
    return STAGE_HELD;
}

uint8_t proto_accept(const uint8_t *payload, uint8_t len)
{
    if (!machine.synced) {
        session_boot_on_data();
        return PROTO_REFUSED;
    }
    /* The step engine: a segment whose block finds no room in the ring of chunks waits
     * with its frame (proto_execute), and the ring frees only as the steppers run; while
     * the queue holds still (a heating wait) the frames behind it, held too, filled the
     * deframer, the host's next frames stayed in the UART and its watchdog tripped on a
     * host that spoke all along (the first layer at its heating wait). Refused (the host
     * sends it again), a frame leaves the room a next one needs. */
    uint8_t no_room = STEP_ENGINE && blocks_stalled && !deframer_room_behind(len);
    struct seg_ctx work = pend.check;
    uint8_t queued = 0, bad_op = 0, bad_at = 0, wrong;
    uint8_t staged = no_room || pend.n == HELD_FRAMES ? STAGE_NO
                                                      : stage_segments(payload, len, &work, &queued);
    if (staged == STAGE_QUEUED) {
        ctx = pend.check = work;
        return PROTO_DONE;
    }
    if (staged == STAGE_HELD) {
        pend.staged++;
        /* every frame before it is executed or staged: the next decode at execution
         * (an unstaged frame, behind all staged ones) starts from here */
        ctx = work;
        goto held;
    }
    work = pend.check;
    if (!check_payload(payload, len, &work, &queued, &bad_op, &bad_at, &wrong)) {
        machine_fail(ERR_BAD_COMMAND, machine.items_received, machine.segments_received, bad_op, bad_at);
        return PROTO_DONE;
    }
    if (wrong) {
        machine_fail(ERR_BAD_COMMAND, machine.items_received, 0, wrong, 0);
        return PROTO_DONE;
    }
    if ((queued > machine_free() && !machine.fault) || pend.n == HELD_FRAMES || no_room) {
        machine.overflow_rejects++;
        return PROTO_REFUSED;
    }
held:
    pend.check = work;
    pend.items[(uint8_t)(pend.head + pend.n) % HELD_FRAMES] = queued;
    pend.n++;
    pend.items_total += queued;
    return PROTO_PENDING;
}

/* one queue item of the frame being executed was taken */
static void took_item(void)
{
    pend.items[pend.head]--;
    pend.items_total--;
}

#if STEP_ENGINE
/* The step engine: a WAIT item executes (a heater), so the steppers stand still and the
 * ring of chunks frees nothing until it ends. A segment whose block finds no room then
 * does not wait for it: behind a heating wait the queued ramps' blocks filled the ring,
 * the next segment's frame waited (held), the frames after it were held or refused, and
 * the device heard no frame of the host's for longer than its watchdog (the first layer
 * at its heating wait, segment 154), or the lease renewals waited behind it until the
 * lease ran out. Its block is checked and left out instead, and the tick's DDA steps its
 * axes (PROTOCOL.md 5.5, an axis without a block). */
static uint8_t queue_holds_still(void)
{
    uint8_t heater, s = SREG;
    uint16_t tolerance;
    cli();
    uint8_t wait = stepper_waiting_for(&heater, &tolerance);
    SREG = s;
    return wait != WAIT_NONE;
}

/* The segment at r->pos, which carries a schedule block, decoded into `s`, its block's
 * chunks into the steppers' ring (step_blocks.h). The ring reserves only what the block
 * takes: it is read into the free run at the ring's head, and when it turns out longer
 * (blocks_sink_short), read again where it fits, or it waits, its size known, until the
 * steppers have freed that much (it reserved the most the rest of its frame could hold,
 * up to 42 entries, and waited for that room in a fifth of the first layer's motion:
 * its frame held, the next ones refused for the deframer's room and sent again).
 * Returns 0 while it waits (r->pos and the coder context as they were). */
static uint8_t __attribute__((noinline)) decode_with_block(struct reader *r, struct segment *s)
{
    uint8_t at = r->pos;
    struct seg_ctx from = ctx;
    for (;;) {
        segment_sched_out = blocks_sink(pend.block_need);
        if (!segment_sched_out) {
            if (!queue_holds_still())
                return 0;
            /* its axes on the tick's DDA, as an axis the host sent no block for */
            segment_decode(r, &ctx, s);
            s->sched.mask = 0;
            blocks_stalled = 0; /* (nothing waits for the ring) */
            break;
        }
        segment_decode(r, &ctx, s); /* checked before: it decodes */
        segment_sched_out = 0;
        uint8_t need = blocks_sink_short();
        if (!need)
            break;
        pend.block_need = need;
        r->pos = at;
        ctx = from;
    }
    pend.block_need = 0;
    return 1;
}
#endif

static void __attribute__((noinline)) execute_held(uint16_t units)
{
    struct reader *r = &pend.r;
    struct segment s;
    struct message_desc m;
    uint32_t v[MAX_VALUES];
    uint32_t start = sched_clock();
    for (;;) {
        if (!pend.active) {
            uint8_t len;
            const uint8_t *payload = deframer_first(&len);
            if (!payload || !pend.n)
                return;
            r->buf = payload;
            r->pos = 0;
            r->len = len;
            r->err = 0;
            pend.active = 1;
        }
        if (pend.staged) {
            /* a staged frame: its segments wait in the queue, decoded */
            while (pend.items[pend.head]) {
                motion_prepare_ahead(1);
                took_item();
                enqueue_staged();
                if (sched_clock() - start >= units)
                    return; /* the rest next turn */
            }
            r->pos = r->len;
        }
        while (r->pos < r->len) {
            /* the plans first: they are what the interrupt waits on */
            motion_prepare_ahead(1);
            uint8_t op = r->buf[r->pos];
            if (op >= SEG_BASE) {
#if STEP_ENGINE
                if (op & SEG_F_SCHEDULE) {
                    if (!decode_with_block(r, &s))
                        return; /* its block waits for room in the steppers' ring of chunks */
                } else
#endif
                {
                    segment_decode(r, &ctx, &s); /* checked before: it decodes */
                    segment_sched_out = 0;
                }
                took_item();
                enqueue_segment(&s);
            } else {
                find(op, &m);
                r->pos++;
                parse_fields(r, &m, v);
                if (m.queued) {
                    took_item();
                    enqueue_command(op, v);
                } else {
                    immediate(op, v);
                }
            }
            if (sched_clock() - start >= units)
                break;
        }
        if (r->pos < r->len)
            return; /* the rest next turn: the main loop's other work goes on */
        pend.active = 0;
        if (pend.staged)
            pend.staged--;
        pend.items_total -= pend.items[pend.head]; /* 0 unless a fault discarded some */
        pend.head = (uint8_t)(pend.head + 1) % HELD_FRAMES;
        pend.n--;
        deframer_pop();
        if (sched_clock() - start >= units)
            return;
    }
}

void proto_execute(uint16_t units)
{
    /* every main-loop turn, most with nothing held (execute_held's frame and its clock
     * read cost an idle turn about 130 cycles) */
    if (pend.active || pend.n)
        execute_held(units);
}

void proto_urgent(const uint8_t *payload, uint8_t len)
{
    struct reader r = {payload, 0, len, 0};
    struct message_desc m;
    uint32_t v[MAX_VALUES];
    uint8_t op = rd_u8(&r);
    if (r.err || !find(op, &m) || !m.urgent)
        return;
    parse_fields(&r, &m, v);
    if (r.err || r.pos != len)
        return; /* exactly one well-formed message */
    if (op == OP_HELLO) {
        uint16_t nonce = (uint16_t)v[0];
        if (!machine.synced)
            session_boot_before_ident();
        if (v[1] == PROTO_MAJOR && (!machine.synced || nonce != machine.nonce)) {
            link_reset_session();
            commands_reset_session();
            session_opened();
            machine.synced = 1;
            machine.nonce = nonce;
            machine.host_minor = (uint8_t)v[2] > PROTO_MINOR ? PROTO_MINOR : (uint8_t)v[2];
        }
        report_ident(nonce, 1);
    } else { /* OP_EMERGENCY_STOP */
        if (!machine.estopped) {
            /* the motors stay enabled unless the host asks to release them */
            machine_stop(ERR_ESTOP, v[0] & ESTOP_KEEP_HEATERS, !(v[0] & ESTOP_RELEASE_MOTORS), 0);
            machine.estopped = 1;
        }
        report_estop_ack();
    }
}
