/* What the simulation harness may read from RAM (its address is left in
 * GPIOR1:GPIOR2 at boot). The record itself is built from pin edges; the
 * mailbox only names segments (their protocol numbers), the positions a
 * SET_POSITION or HOME set, and figures for the benchmark. */
#ifndef MAILBOX_H
#define MAILBOX_H
#include <stdint.h>

struct sim_mailbox {
    uint8_t magic[4]; /* "CDPR" */
    uint32_t seq;     /* segment number of the marker edge in progress */
    int32_t pos[4];   /* positions after the last SET_POSITION / HOME */
    uint8_t last_error;
    uint8_t version;
    uint16_t isr_max_cycles;
    uint16_t lost_steps;
    uint16_t main_loop_max_us;
    uint32_t segments_parsed;
    uint16_t speedup_x16; /* written by the harness: device time / link time x 16 */
    uint16_t plan_stalls;
    uint16_t overruns;
    uint32_t link_clock; /* written by the harness: wall time in clock units (link_valid set) */
    uint8_t link_valid;
    uint8_t latency_max;
    uint8_t edge; /* what the next MARK_EDGE toggle means: EDGE_* */
    uint16_t late_pulses; /* step pulses issued after their tick ended (never lost) */
    uint16_t stack_free;  /* bytes of the painted gap below the stack never written */
};
extern volatile struct sim_mailbox sim_mailbox;

#define EDGE_SEG_END 0x01      /* a segment's last tick ended: seq names it */
#define EDGE_MOTION_START 0x02 /* the first tick of motion begins */
#define EDGE_MOTION_STOP 0x04  /* the last tick of motion ended */

#endif
