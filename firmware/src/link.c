#include <string.h>

#include "frame.h"
#include "link.h"
#include "sched.h"
#include "uart.h"

#define T_MS(ms) ((uint32_t)(ms) * (CLOCK_HZ / 1000))
#define RTO_INITIAL T_MS(50)
#define RTO_FLOOR T_MS(20)
#define RTO_CEILING T_MS(250)
#define NAK_HOLDOFF T_MS(10) /* PROTOCOL.md 2: at most once per expected number per 10 ms */

struct link_counters link_counters;
uint32_t link_now; /* the link's clock (sched.h), kept by the main loop */
static const struct link_upper *upper;

void link_attach(const struct link_upper *u)
{
    upper = u;
}

struct slot {
    uint8_t len;
    uint8_t retransmitted;
    uint8_t important; /* an error report */
    uint32_t sent_at;
    uint8_t data[REPORT_MAX];
};
static struct slot slots[REPORT_SLOTS];
static uint8_t first;       /* index of the oldest slot (outstanding first, then backlog) */
static uint8_t n_out, n_back;
/* error reports not sent yet: a FLOW (whose flags and counts show the fault) waits for
 * them, so the host never sees the effect of a fault before its cause */
static uint8_t errors_unsent;
static uint8_t base_seq, next_seq;
static uint8_t expected;
static uint8_t ack_due, nak_due, resend;
/* An in-order frame's ACK waits for the next frame's when that one's bytes are already
 * coming in (one cumulative ACK for both: the replies with their FLOW cost about 200
 * cycles less a 0.5 ms segment so, bench/stream_rates.py --profile): ACK_HELD while the
 * turn that checked the frame ends, ACK_HELD_TURN after it; the next frame checked or the
 * next turn's link_poll sends it, so an ACK waits one turn (unless, as any reply, it
 * finds no room in the UART). */
enum { ACK_SENT, ACK_HELD, ACK_HELD_TURN };
static uint8_t ack_held;
static uint8_t last_nak_expected;
static uint32_t last_nak_at;
static uint8_t went_back_seq;
static uint32_t went_back_at;
static uint8_t have_srtt;
static uint32_t srtt, rttvar, rto_base;
static uint8_t backoff;
/* when an acknowledgement last released reports: the timer restarts there (RFC 6298 5.3) */
static uint32_t advanced_at;

static uint8_t urgent_len;
static uint8_t urgent_buf[REPORT_MAX];
/* an error report that found every slot taken by other error reports: sent as soon as a
 * slot frees (errors_unsent counts it), so a burst of errors loses none */
static uint8_t held_len;
static uint8_t held_error[CDPR_ERROR_MAX_LEN];

static uint32_t rto(void)
{
    uint32_t b = rto_base < RTO_FLOOR ? RTO_FLOOR : rto_base;
    b *= backoff;
    return b > RTO_CEILING ? RTO_CEILING : b;
}

void link_reset_session(void)
{
    first = n_out = n_back = errors_unsent = held_len = 0;
    base_seq = next_seq = 0;
    expected = 0;
    ack_due = nak_due = resend = 0;
    ack_held = ACK_SENT;
    last_nak_expected = 0xFF;
    last_nak_at = 0;
    went_back_seq = 0;
    went_back_at = 0;
    have_srtt = 0;
    srtt = rttvar = 0;
    rto_base = RTO_INITIAL;
    backoff = 1;
    went_back_at = link_now - T_MS(10000);
    last_nak_at = went_back_at;
    advanced_at = went_back_at;
}

/* The newest unsent report that is not an error, removed (the newer ones move down
 * one slot, keeping their order); 0 when every unsent report is an error. */
static uint8_t evict_one(void)
{
    for (int8_t i = (int8_t)n_back - 1; i >= 0; i--) {
        if (slots[(first + n_out + (uint8_t)i) % REPORT_SLOTS].important)
            continue;
        for (uint8_t j = (uint8_t)i; j + 1 < n_back; j++)
            slots[(first + n_out + j) % REPORT_SLOTS] =
                slots[(first + n_out + j + 1) % REPORT_SLOTS];
        n_back--;
        return 1;
    }
    return 0;
}

uint8_t link_send(const uint8_t *payload, uint8_t len, uint8_t important)
{
    if (len > REPORT_MAX)
        return 0;
    if (n_out + n_back >= REPORT_SLOTS) {
        if (!important)
            return 0;
        /* an error report takes the place of the newest unsent report that is not one;
         * with none, it waits in held_error */
        if (!evict_one()) {
            if (held_len || len > sizeof held_error)
                return 0; /* more errors in one burst than REPORT_SLOTS + 1 */
            memcpy(held_error, payload, len);
            held_len = len;
            errors_unsent++;
            return 1;
        }
    }
    struct slot *s = &slots[(first + n_out + n_back) % REPORT_SLOTS];
    memcpy(s->data, payload, len);
    s->len = len;
    s->retransmitted = 0;
    s->important = important ? 1 : 0;
    errors_unsent += s->important;
    n_back++;
    return 1;
}

void link_send_urgent(const uint8_t *payload, uint8_t len)
{
    if (len <= sizeof urgent_buf) {
        memcpy(urgent_buf, payload, len);
        urgent_len = len;
    }
}

void link_flush_urgent(void)
{
    if (urgent_len && uart_tx_free() >= FRAME_SIZE(urgent_len)) {
        frame_send(KIND_URGENT, 0, expected, urgent_buf, urgent_len);
        urgent_len = 0;
    }
}

void link_request_ack(void)
{
    ack_due = 1;
}

static void rto_sample(uint32_t rtt)
{
    if (!have_srtt) {
        srtt = rtt;
        rttvar = rtt / 2;
        have_srtt = 1;
    } else {
        uint32_t diff = srtt > rtt ? srtt - rtt : rtt - srtt;
        rttvar = (3 * rttvar + diff) / 4;
        srtt = (7 * srtt + rtt) / 8;
    }
    uint32_t v4 = 4 * rttvar;
    rto_base = srtt + (v4 > T_MS(2) ? v4 : T_MS(2));
    backoff = 1;
}

static void on_ack(uint8_t ack, uint32_t now)
{
    uint8_t n = (uint8_t)(ack - base_seq);
    if (n == 0 || n > n_out)
        return;
    struct slot *last = &slots[(first + n - 1) % REPORT_SLOTS];
    if (!last->retransmitted)
        rto_sample(now - last->sent_at);
    else
        backoff = 1;
    first = (uint8_t)((first + n) % REPORT_SLOTS);
    n_out -= n;
    base_seq += n;
    advanced_at = now;
}

static uint8_t send_ack(uint32_t now);

static void want_nak(uint32_t now)
{
    if (last_nak_expected != expected || now - last_nak_at >= NAK_HOLDOFF)
        nak_due = 1;
}

void link_frame_rejected(uint8_t kind, uint8_t seq)
{
    if (kind == KIND_DATA && seq == expected)
        want_nak(link_now);
}

uint8_t link_frame_received(uint8_t kind, uint8_t seq, uint8_t ack, const uint8_t *payload,
                           uint8_t len)
{
    uint32_t now = link_now;
    upper->frame_seen();
    if (kind == KIND_URGENT) {
        upper->urgent(payload, len);
        return 0;
    }
    on_ack(ack, now);
    if (kind == KIND_NAK && n_out && base_seq == ack) {
        uint32_t holdoff = (have_srtt ? srtt : rto()) / 2;
        if (!(went_back_seq == ack && now - went_back_at < holdoff)) {
            resend = 1;
            went_back_seq = base_seq;
            went_back_at = now;
        }
    }
    if (kind != KIND_DATA)
        return 0;
    uint8_t d = (uint8_t)(seq - expected), hold = 0;
    if (d == 0) {
        /* checked (every field, room for its items): acknowledged at once, before it
         * is executed, so the host's window moves on while the device works */
        uint8_t verdict = upper->accept(payload, len);
        if (verdict) {
            expected++;
            hold = verdict == PROTO_PENDING;
        } else {
            link_counters.rejected++;
        }
        ack_due = 1;
        if (verdict && ack_held == ACK_SENT && deframer_more_behind(len))
            ack_held = ACK_HELD;
        else
            send_ack(now);
    } else if (d > MAX_WINDOW) {
        link_counters.duplicates++;
        ack_due = 1;
    } else {
        want_nak(now);
    }
    return hold;
}

/* The ACK (or NAK) with FLOW that is due, now if the UART has room. */
static uint8_t send_ack(uint32_t now)
{
    uint8_t flow[FLOW_MAX];
    if (!(nak_due || ack_due))
        return 1;
    if (errors_unsent && !nak_due)
        return 0; /* after the error reports (link_poll sends them as the window opens) */
    if (uart_tx_free() < FRAME_SIZE(sizeof flow))
        return 0;
    uint8_t n = upper->flow(flow);
    if (nak_due) {
        frame_send(KIND_NAK, 0, expected, flow, n);
        link_counters.naks_sent++;
        last_nak_expected = expected;
        last_nak_at = now;
    } else {
        frame_send(KIND_ACK, 0, expected, flow, n);
    }
    nak_due = ack_due = 0;
    ack_held = ACK_SENT;
    return 1;
}

void link_poll(uint32_t now)
{
    if (held_len && n_out + n_back < REPORT_SLOTS) {
        uint8_t n = held_len;
        held_len = 0;
        errors_unsent--;
        link_send(held_error, n, 1);
    }
    link_flush_urgent();
    if (urgent_len)
        return; /* no room for it yet: it goes first */
    /* the oldest report's time, or the last progress if that came later */
    uint32_t since = slots[first].sent_at;
    if ((int32_t)(advanced_at - since) > 0)
        since = advanced_at;
    if (n_out && !resend && now - since >= rto()) {
        if (backoff < 64)
            backoff *= 2;
        resend = 1;
        went_back_seq = base_seq;
        went_back_at = now;
    }
    if (resend) {
        for (uint8_t i = 0; i < n_out; i++) {
            struct slot *s = &slots[(first + i) % REPORT_SLOTS];
            if (uart_tx_free() < FRAME_SIZE(s->len))
                return; /* the rest goes next time round */
            frame_send(KIND_DATA, (uint8_t)(base_seq + i), expected, s->data, s->len);
            s->sent_at = now;
            s->retransmitted = 1;
            link_counters.retransmits++;
        }
        resend = 0;
    }
    while (n_back && n_out < DEV_WINDOW) {
        struct slot *s = &slots[(first + n_out) % REPORT_SLOTS];
        if (uart_tx_free() < FRAME_SIZE(s->len))
            return;
        frame_send(KIND_DATA, next_seq, expected, s->data, s->len);
        s->sent_at = now;
        next_seq++;
        n_out++;
        n_back--;
        errors_unsent -= s->important;
    }
    if (ack_held == ACK_HELD && !nak_due)
        ack_held = ACK_HELD_TURN; /* the next frame's covers it */
    else if (nak_due || ack_due) /* (send_ack's frame costs a turn with none 50 cycles) */
        send_ack(now);
}
