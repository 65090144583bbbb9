/* The simulator's hooks: what the simavr harness (firmware/sim) reads from and
 * writes to the mailbox (mailbox.h). Compiled in only for the simulator target
 * (build/cdpr-sim.elf, -DCDPR_SIM_HOOKS); on the board target (build/cdpr.elf,
 * the one flashed) every hook is an empty inline function, so the step interrupt
 * and the main loop pay nothing for them and the mailbox does not exist. */
#ifndef SIM_HOOKS_H
#define SIM_HOOKS_H
#include <stdint.h>

#ifdef CDPR_SIM_HOOKS
#include <avr/interrupt.h>
#include <avr/io.h>

#include "mailbox.h"

/* leave the mailbox's address in GPIOR1:GPIOR2 and mark it for the harness */
static inline void sim_boot(void)
{
    GPIOR1 = (uint8_t)((uint16_t)&sim_mailbox);
    GPIOR2 = (uint8_t)((uint16_t)&sim_mailbox >> 8);
    sim_mailbox.magic[0] = 'C';
    sim_mailbox.magic[1] = 'D';
    sim_mailbox.magic[2] = 'P';
    sim_mailbox.magic[3] = 'R';
    sim_mailbox.version = 1;
    extern uint8_t _end;
    sim_mailbox.canary_at = (uint16_t)&_end;
}

/* The harness keeps the wall clock in the mailbox: the link's timers
 * (retransmission, announcements, host watchdog) then run in real time whatever
 * the simulation's speed, as the Python model's do. The harness writes it between
 * any two instructions (masking interrupts does not stop it), so a read of its four
 * bytes can straddle an update: a carry into the third byte read half old, half new
 * is a jump of 0.66 s, which once stored as a frame's time put the host watchdog's
 * "now - last frame" below zero (a huge unsigned) and stopped a healthy stream. Read
 * until two reads agree. */
static inline uint32_t sim_link_clock(uint32_t t)
{
    if (sim_mailbox.link_valid) {
        uint32_t again;
        do {
            t = sim_mailbox.link_clock;
            again = sim_mailbox.link_clock;
        } while (t != again);
    }
    return t;
}

static inline void sim_segment_parsed(void) { sim_mailbox.segments_parsed++; }
static inline void sim_last_error(uint8_t code) { sim_mailbox.last_error = code; }
static inline void sim_loop_max_us(uint16_t us) { sim_mailbox.main_loop_max_us = us; }

/* Hooks whose sources are volatile take pointers or are macros, so the board
 * target never reads them (a volatile argument would be read even by an empty
 * function). */

/* the positions a SET_POSITION or HOME set (a macro: the same code as the copy
 * written out, in the step interrupt's planner) */
#define SIM_POSITIONS(pos_)                  \
    do {                                     \
        for (uint8_t k_ = 0; k_ < 4; k_++)   \
            sim_mailbox.pos[k_] = (pos_)[k_]; \
    } while (0)

/* a segment's last tick: its number and the motion clock through it */
static inline void sim_segment_end(uint32_t seq, const volatile uint32_t *motion_ticks)
{
    sim_mailbox.seq = seq;
    sim_mailbox.motion_ticks = *motion_ticks;
    sim_mailbox.edge = EDGE_SEG_END;
}

/* motion starts (next) or stops at the armed edge; a fresh edge when not armed */
static inline void sim_motion_edge(uint8_t armed, uint8_t next)
{
    if (!armed)
        sim_mailbox.edge = 0;
    sim_mailbox.edge |= next ? EDGE_MOTION_START : EDGE_MOTION_STOP;
}

/* the main loop's figures, every turn (a macro: the board never reads the
 * volatile counters) */
#define SIM_STATS(isr_max_, lost_, stalls_, overruns_, late_, latency_, error_) \
    do {                                                                         \
        sim_mailbox.isr_max_cycles = (isr_max_);                                 \
        sim_mailbox.lost_steps = (lost_);                                        \
        sim_mailbox.plan_stalls = (stalls_);                                     \
        sim_mailbox.overruns = (overruns_);                                      \
        sim_mailbox.late_pulses = (late_);                                       \
        sim_mailbox.latency_max = (latency_);                                    \
        sim_mailbox.last_error = (error_);                                       \
    } while (0)
static inline void sim_stack_free(uint16_t bytes) { sim_mailbox.stack_free = bytes; }
#define SIM_HOOKS 1 /* for work done only to feed a hook: if (SIM_HOOKS) ... */

#else /* the board: no mailbox, no cost */

static inline void sim_boot(void) {}
static inline uint32_t sim_link_clock(uint32_t t) { return t; }
static inline void sim_segment_parsed(void) {}
static inline void sim_last_error(uint8_t code) { (void)code; }
static inline void sim_loop_max_us(uint16_t us) { (void)us; }
#define SIM_POSITIONS(pos_) ((void)0)
static inline void sim_segment_end(uint32_t seq, const volatile uint32_t *motion_ticks)
{
    (void)seq;
    (void)motion_ticks;
}
static inline void sim_motion_edge(uint8_t armed, uint8_t next) { (void)armed; (void)next; }
#define SIM_STATS(isr_max_, lost_, stalls_, overruns_, late_, latency_, error_) ((void)0)
static inline void sim_stack_free(uint16_t bytes) { (void)bytes; }
#define SIM_HOOKS 0

#endif
#endif
