/* Reliable ordered delivery, device side: in-order receiver with NAKs, a
 * go-back-N sender for the device's reports with an RFC 6298 timeout. The same
 * rules as firmware_protocol/reliability.py and endpoint.py. Times are ticks. */
#ifndef LINK_H
#define LINK_H
#include <stdint.h>

#include "config.h"
#include "protocol_gen.h"

#if STEP_ENGINE /* a FLOW payload's bytes at most, with RING after it (3.2) */
#define FLOW_MAX (CDPR_FLOW_MAX_LEN + CDPR_RING_MAX_LEN)
#else
#define FLOW_MAX CDPR_FLOW_MAX_LEN
#endif

struct link_counters {
    uint16_t retransmits, naks_sent, duplicates, rejected;
};
extern struct link_counters link_counters;

void link_reset_session(void);
void link_poll(uint32_t now);                 /* send what is due */
uint8_t link_send(const uint8_t *payload, uint8_t len, uint8_t important); /* 0: dropped */
void link_send_urgent(const uint8_t *payload, uint8_t len);
/* The urgent message waiting, framed into the UART now when it has room (the next
 * link_send_urgent would replace it). */
void link_flush_urgent(void);
void link_request_ack(void);

/* What the link hands up, registered by the layer above (the transport never calls up
 * into command execution by name: main.c wires it). */
enum { PROTO_REFUSED, PROTO_DONE, PROTO_PENDING };
struct link_upper {
    /* a DATA frame in order: PROTO_REFUSED leaves it unacknowledged (no room), PROTO_DONE
     * acknowledges it, PROTO_PENDING acknowledges it and keeps its bytes until executed */
    uint8_t (*accept)(const uint8_t *payload, uint8_t len);
    void (*urgent)(const uint8_t *payload, uint8_t len);
    uint8_t (*flow)(uint8_t *out); /* FLOW payload (out[FLOW_MAX]) for ACK/NAK frames */
    void (*frame_seen)(void);      /* any valid frame: feeds the host watchdog */
};
void link_attach(const struct link_upper *upper);
/* The deframer's frames (struct frame_upper, wired by main.c). */
uint8_t link_frame_received(uint8_t kind, uint8_t seq, uint8_t ack, const uint8_t *payload,
                            uint8_t len);
void link_frame_rejected(uint8_t kind, uint8_t seq);

#endif
