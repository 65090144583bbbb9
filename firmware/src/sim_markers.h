/* The markers the simulator's harness builds its executed-segment record from
 * (board_ramps14.h, MARK_*), set at step tick boundaries by the step interrupt.
 * MARK_EDGE is timer 1's compare C output: OCR1C set a few cycles into the next tick
 * toggles it exactly at that boundary whatever the interrupt's latency (simavr only
 * arms a compare whose time has not passed when its timer period starts, and that
 * start may be seen a few cycles late), when the tick ends a segment or motion starts
 * or stops there; sim_hooks.h leaves which of these it was for the harness. MARK_POS
 * and MARK_ABORT are toggled by software at rest. The board target drives none of
 * these pins (OC1C stays disconnected: the LED is left alone). */
#ifndef SIM_MARKERS_H
#define SIM_MARKERS_H
#include <avr/io.h>
#include <stdint.h>

#include "board_ramps14.h"
#include "sim_hooks.h"
#include "step_wheel.h"

#define EDGE_AT_NEXT_TICK 8
#define EDGE_NEVER 0xFFFF /* above any TOP: no match */

/* OCR1C is set to toggle MARK_EDGE at the next tick boundary */
extern uint8_t marker_edge_armed;

/* The marker pins as outputs (the simulator target only). */
void markers_init(void);

/* At the start of the tick `now` (interrupts on): positions set and a segment abandoned
 * are marked at once; MARK_EDGE is armed for the boundary that ends the tick if it ends
 * a segment (the motion clock through it with it), else disarmed. */
static inline __attribute__((always_inline)) void markers_tick_start(
    const struct out *now, const volatile uint32_t *motion_ticks)
{
    uint8_t f = now->flags;
    if (SIM_HOOKS && (f & (OUT_POS | OUT_ABORT))) {
        if (f & OUT_ABORT)
            MARK_ABORT_PIN = _BV(MARK_ABORT_BIT);
        if (f & OUT_POS)
            MARK_POS_PIN = _BV(MARK_POS_BIT);
    }
    if (f & OUT_SEG_END) {
        sim_segment_end(now->seq, motion_ticks);
        marker_edge_armed = 1;
        OCR1C = EDGE_AT_NEXT_TICK;
    } else if (marker_edge_armed) {
        marker_edge_armed = 0;
        OCR1C = EDGE_NEVER;
    }
}

/* After the next tick was computed: MARK_EDGE toggles at the boundary between the two
 * if motion starts or stops there. */
static inline __attribute__((always_inline)) void markers_motion_change(
    const struct out *now, const struct out *next)
{
    uint8_t moving_next = next->flags & OUT_MOTION;
    if (moving_next == (now->flags & OUT_MOTION))
        return;
    sim_motion_edge(marker_edge_armed, moving_next);
    marker_edge_armed = 1;
    OCR1C = EDGE_AT_NEXT_TICK;
}

#endif
