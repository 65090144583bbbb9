/* What the simulation harness may read from RAM (its address is left in
 * GPIOR1:GPIOR2 at boot). The record's positions are built from pin edges; the
 * mailbox names segments (their protocol numbers) and the motion clock at
 * their end, the positions a SET_POSITION or HOME set, and figures for the
 * benchmark. */
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
    uint32_t motion_ticks; /* motion clock (units) at the end of segment `seq` */
    uint16_t canary_at;    /* the stack canary's address (the end of static RAM) */
};
extern volatile struct sim_mailbox sim_mailbox;

/* the harness's view of this struct (one definition, checked here at compile time) */
#include <stddef.h>
#include "../sim/mailbox_layout.h"
#define MB_CHECK(field, off) _Static_assert(offsetof(struct sim_mailbox, field) == off, #field)
MB_CHECK(seq, MB_SEQ);
MB_CHECK(pos, MB_POS);
MB_CHECK(last_error, MB_LAST_ERROR);
MB_CHECK(isr_max_cycles, MB_ISR_MAX);
MB_CHECK(lost_steps, MB_LOST_STEPS);
MB_CHECK(main_loop_max_us, MB_LOOP_MAX_US);
MB_CHECK(segments_parsed, MB_SEGMENTS_PARSED);
MB_CHECK(speedup_x16, MB_SPEEDUP_X16);
MB_CHECK(plan_stalls, MB_PLAN_STALLS);
MB_CHECK(overruns, MB_OVERRUNS);
MB_CHECK(link_clock, MB_LINK_CLOCK);
MB_CHECK(link_valid, MB_LINK_VALID);
MB_CHECK(latency_max, MB_LATENCY_MAX);
MB_CHECK(edge, MB_EDGE);
MB_CHECK(late_pulses, MB_LATE_PULSES);
MB_CHECK(stack_free, MB_STACK_FREE);
MB_CHECK(motion_ticks, MB_MOTION_TICKS);
MB_CHECK(canary_at, MB_CANARY_AT);
_Static_assert(sizeof(struct sim_mailbox) == MB_SIZE, "mailbox size");
#undef MB_CHECK


#endif
