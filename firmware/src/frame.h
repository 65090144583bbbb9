/* Frames on the wire: a resynchronising deframer and the frame writer. */
#ifndef FRAME_H
#define FRAME_H
#include <stdint.h>

#include "protocol_gen.h"

#define FRAME_MAX (FRAME_OVERHEAD + FRAME_MAX_PAYLOAD)
#define DEFRAME_BUF (2 * FRAME_MAX + 6)

struct deframer_stats {
    uint32_t frames, bad_headers, bad_frames;
};
extern struct deframer_stats deframer_stats;

/* What the deframer hands up, registered by the layer above (the link; main.c wires
 * it): each valid frame (returns 1 to hold its bytes, acknowledged, until it has been
 * executed: deframer_first / deframer_pop), and each frame with a good header and a
 * bad body. */
struct frame_upper {
    uint8_t (*received)(uint8_t kind, uint8_t seq, uint8_t ack, const uint8_t *payload,
                        uint8_t len);
    void (*rejected)(uint8_t kind, uint8_t seq);
    /* between the candidates of one deframer_run (each costs a CRC, and a damaged
     * stream has many): the work above that cannot wait that long */
    void (*meanwhile)(void);
};
void deframer_attach(const struct frame_upper *upper);

void deframer_receive(void); /* the UART's received bytes, as many as there is room for */
void deframer_run(void);
/* The oldest held frame's payload (0: none held); valid until deframer_pop(). */
const uint8_t *deframer_first(uint8_t *len);
void deframer_pop(void);        /* the oldest held frame was executed */
void deframer_drop_held(void);  /* a new session: forget the held frames */
/* Whether the frame being checked (a payload of `len`, right behind the held frames),
 * held too, would leave room behind it for a whole frame of the longest payload: while
 * the held frames cannot be executed, the host's next frames must still come in, or the
 * device stops hearing it (its watchdog counts frames received). */
uint8_t deframer_room_behind(uint8_t len);
/* Whether bytes of another frame have come in behind the frame being checked (a payload
 * of `len`, right behind the held frames): the next main-loop turn checks that one. */
uint8_t deframer_more_behind(uint8_t len);

/* Bytes a frame of this payload takes on the wire. */
#define FRAME_SIZE(len) ((uint16_t)(len) + FRAME_OVERHEAD)
/* Write one frame to the UART (caller checked uart_tx_free() >= FRAME_SIZE(len)). */
void frame_send(uint8_t kind, uint8_t seq, uint8_t ack, const uint8_t *payload, uint8_t len);

#endif
