/* The move queue's execution, one step tick at a time: what each tick does, computed
 * one tick ahead (step_timer.c times the ticks and issues their steps, the interrupt
 * step_tick_isr.c runs both).
 *
 * A tick is TICK_UNITS clock units long, except the last tick of a segment or dwell,
 * which is as long as the item needs, so items start and end on exact clock units.
 * Each step has its own time: the DDA counts a tick's steps per axis and places each
 * at the time the segment's profile gives it (interpolated inside the tick from the
 * accumulator and the axis's cycles per step), on a time wheel of SLOT_CYCLES slots;
 * the axes that fall in one slot form one event of the tick's list. Between segments
 * the tick starts the queue's other items (positions, enables, heater targets, the
 * fan, dwells, homing, waits).
 *
 * At each tick's start it also advances the scheduler's clock (sched.h) and the heater
 * lease (lease.h) and sets the simulator's markers (sim_markers.h); homing (homing.c)
 * and the limit switches (limits.c) have their own files and state. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/pgmspace.h>

#include "board_ramps14.h"
#include "config.h"
#include "homing.h"
#include "lease.h"
#include "limits.h"
#include "mul16.h"
#include "pwm.h"
#include "sim_hooks.h"
#include "sim_markers.h"
#include "step_pins.h"
#include "step_blocks.h"
#include "step_engine.h"
#include "step_events.h"
#include "step_rate.h"
#include "step_tick.h"
#include "step_timer.h"
#include "step_wheel.h"
#include "motion.h"
#include "protocol_gen.h"
#include "queue.h"
#include "sched.h"
#include "stepper.h"

/* What the interrupt executes and has executed. It owns this state: the main loop
 * reads it through stepper_progress and stepper_positions, and changes it only with
 * the interrupt masked (halt, flush, disable). */
struct stepper_state {
    int32_t pos[4];            /* logical step positions */
    uint32_t items_done, segments_done;
    uint32_t seg_next;         /* the number the next executed segment has (PROTOCOL.md 4,
                                  Numbering: refused and flushed segments keep theirs) */
    uint32_t motion_ticks;     /* executed durations, clock units */
    uint8_t enabled_mask, homed_mask;
    uint8_t at_rest;           /* the last executed motion ended at rest */
    uint8_t running;           /* 0: fault / estop: execute nothing */
    uint8_t current;           /* kind of the executing timed item, or 0xFF */
    uint8_t wait_heater;       /* WAIT item executing: heater id */
    uint16_t wait_tolerance;
};
static volatile struct stepper_state stepper;

/* SET_HEATER items executed, on their way to the main loop's heater control */
static volatile uint16_t heater_targets[2];
static volatile uint8_t heater_targets_changed; /* heater bit set: a target to take */

volatile struct stepper_report stepper_report;
#if STEP_ENGINE
volatile uint8_t stepper_start_for;
#else
volatile uint8_t stepper_start_ok;
#endif
volatile uint8_t stepper_wait_ok;
volatile uint16_t stepper_lost_steps, stepper_plan_stalls;

/* steps the wheel had no room for (never at the advertised rate): counted, not lost
 * silently */
static inline __attribute__((always_inline)) void lost_count(uint8_t lost)
{
    if (lost)
        stepper_lost_steps += lost;
}

/* The main loop's own writes of what a reset keeps (the counts, the enabled drivers):
 * stepper_init, stepper_flush, stepper_disable_all. */
static uint8_t main_changes;

/* the executing item */
static struct plan *seg_plan; /* SEG: its plan */
static uint32_t ticks_left;   /* SEG, DWELL: ticks left */
static uint8_t last_units;    /* DWELL: length of the last tick */
static uint8_t settle_ticks;  /* ticks to wait after positions were set */
static uint8_t abort_pending; /* a segment was abandoned: mark it */
/* the step engine's chunks of the plan at plan_tail are out already (put out during the
 * segment before it) */
static uint8_t chunks_ahead;
/* the next segment's axes (0..4) whose chunks went out during this segment's last ticks */
static uint8_t axes_ahead;
static uint32_t abort_seq;
/* the ring of schedule chunks (step_blocks.h): the blocks of the segments that ended but
 * whose end may not have come yet (their last tick is computed a tick ahead), oldest
 * first: where each segment ends on the steppers' clock and the ring's head after its
 * block. Freed once that time has passed (the steppers take a chunk at the last edge of
 * the one before, so a segment's are all taken by its end). */
#define BLK_HELD 4 /* a segment ends a tick at the most, an entry goes within two */
static uint8_t blk_held;
static struct {
    uint32_t end;
    uint8_t blk_end;
} blk_fifo[BLK_HELD];

void stepper_init(uint8_t hold_mask)
{
    X_STEP_DDR |= _BV(X_STEP_BIT); X_DIR_DDR |= _BV(X_DIR_BIT); X_EN_DDR |= _BV(X_EN_BIT);
    Y_STEP_DDR |= _BV(Y_STEP_BIT); Y_DIR_DDR |= _BV(Y_DIR_BIT); Y_EN_DDR |= _BV(Y_EN_BIT);
    Z_STEP_DDR |= _BV(Z_STEP_BIT); Z_DIR_DDR |= _BV(Z_DIR_BIT); Z_EN_DDR |= _BV(Z_EN_BIT);
    E_STEP_DDR |= _BV(E_STEP_BIT); E_DIR_DDR |= _BV(E_DIR_BIT); E_EN_DDR |= _BV(E_EN_BIT);
    stepper.enabled_mask = hold_mask & 0x0F;
    main_changes++;
    apply_enables(stepper.enabled_mask);
    X_MIN_DDR &= (uint8_t)~_BV(X_MIN_BIT); X_MIN_PORT |= _BV(X_MIN_BIT);
    Y_MIN_DDR &= (uint8_t)~_BV(Y_MIN_BIT); Y_MIN_PORT |= _BV(Y_MIN_BIT);
    Z_MIN_DDR &= (uint8_t)~_BV(Z_MIN_BIT); Z_MIN_PORT |= _BV(Z_MIN_BIT);
    X_MAX_DDR &= (uint8_t)~_BV(X_MAX_BIT); X_MAX_PORT |= _BV(X_MAX_BIT);
    Y_MAX_DDR &= (uint8_t)~_BV(Y_MAX_BIT); Y_MAX_PORT |= _BV(Y_MAX_BIT);
    Z_MAX_DDR &= (uint8_t)~_BV(Z_MAX_BIT); Z_MAX_PORT |= _BV(Z_MAX_BIT);
    markers_init();
    stepper.current = 0xFF;
    stepper.at_rest = 1;
    stepper.running = 1;
    stepper.seg_next = 1;
    step_timer_init();
}

/* Everything but the positions, consistent: no tick interrupt came between the first
 * read and the last (the tick changes them only as a whole; the main loop's own
 * changes mask it). Nothing is masked: a masked copy this long delays compare B. */
void stepper_progress(struct stepper_progress *out)
{
    uint8_t gen;
    do {
        gen = tick_gen;
        out->items_done = stepper.items_done;
        out->segments_done = stepper.segments_done;
        out->motion_ticks = stepper.motion_ticks;
        out->current = stepper.current;
        out->tail = queue_tail; /* (moves with items_done: one snapshot of both) */
        out->ticks_left =
            (out->current == IT_SEG || out->current == IT_DWELL) ? ticks_left : 0;
        out->enabled_mask = stepper.enabled_mask;
        out->homed_mask = stepper.homed_mask;
    } while (gen != tick_gen);
}

uint16_t stepper_change_mark(void)
{
    return (uint16_t)((uint16_t)tick_gen << 8 | main_changes);
}

void stepper_counts(uint32_t *items, uint32_t *segments)
{
    struct stepper_progress done;
    stepper_progress(&done);
    *items = done.items_done;
    *segments = done.segments_done;
}

uint8_t stepper_homed_mask(void)
{
    struct stepper_progress done;
    stepper_progress(&done);
    return done.homed_mask;
}

uint8_t stepper_moving(void)
{
    return stepper.current != 0xFF || !stepper.at_rest;
}

uint8_t stepper_take_heater_targets(uint16_t targets[2])
{
    if (!heater_targets_changed)
        return 0; /* the common case, without masking */
    uint8_t s = SREG;
    cli();
    uint8_t changed = heater_targets_changed;
    targets[0] = heater_targets[0];
    targets[1] = heater_targets[1];
    heater_targets_changed = 0;
    SREG = s;
    return changed;
}

void stepper_drop_heater_targets(void)
{
    uint8_t s = SREG;
    cli();
    heater_targets[0] = heater_targets[1] = 0;
    heater_targets_changed = 0;
    SREG = s;
}

uint8_t stepper_waiting_for(uint8_t *heater, uint16_t *tolerance)
{
    if (stepper.current != IT_WAIT)
        return WAIT_NONE;
    uint8_t id = stepper.wait_heater & 1;
    *heater = id;
    *tolerance = stepper.wait_tolerance;
    return (heater_targets_changed >> id & 1) ? WAIT_TARGET_PENDING : WAIT_HEATER;
}

static void raise_error(uint8_t code, uint32_t item, uint32_t seg, uint8_t axis, int32_t value)
{
    if (stepper_report.error)
        return;
    stepper_report.item = item;
    stepper_report.segment = seg;
    stepper_report.axis = axis;
    stepper_report.value = value;
    stepper_report.error = code;
    stepper.running = 0;
}

/* What the positions mid-segment are made of, taken with interrupts off. */
struct seg_snapshot {
    int32_t pos[4];
    uint8_t running; /* a segment is executing */
    uint8_t acc_int[4];
    uint32_t done_ticks;
    float ka, kb;
    int32_t delta[4];
    uint8_t engine; /* the step engine's axes */
};

static void seg_snapshot(struct seg_snapshot *sn)
{
    for (uint8_t k = 0; k < 4; k++)
        sn->pos[k] = stepper.pos[k];
    sn->running = stepper.current == IT_SEG;
    if (!sn->running)
        return;
    sn->done_ticks = seg_plan->ticks - ticks_left;
    sn->ka = seg_plan->ka;
    sn->kb = seg_plan->kb;
    sn->engine = PLAN_ENGINE(seg_plan);
    for (uint8_t k = 0; k < 4; k++) {
        sn->acc_int[k] = (uint8_t)(seg_plan->ax[k].acc >> 24);
        sn->delta[k] = seg_plan->delta[k];
    }
}

/* The start plus the steps issued so far (the estimate corrected by the low
 * byte the interrupt's accumulator keeps); floating point, interrupts on. */
static void seg_positions(const struct seg_snapshot *sn, int32_t *out)
{
    for (uint8_t k = 0; k < 4; k++) {
        out[k] = sn->pos[k];
        if (!sn->running || !sn->delta[k])
            continue;
        int32_t d = sn->delta[k];
        uint32_t n = (uint32_t)(d < 0 ? -d : d);
        uint32_t est = motion_steps_due((float)n, sn->ka, sn->kb, sn->done_ticks);
        int32_t issued = (int32_t)est;
        if (!(sn->engine >> k & 1)) /* the DDA's own count: its byte corrects */
            issued += (int8_t)(uint8_t)(sn->acc_int[k] - (uint8_t)est);
        out[k] += d < 0 ? -issued : issued;
    }
}

void stepper_positions(int32_t *out)
{
    struct seg_snapshot sn;
    uint8_t gen;
    do {
        gen = tick_gen;
        seg_snapshot(&sn);
    } while (gen != tick_gen);
    seg_positions(&sn, out);
}

#if STEP_ENGINE
/* The chunk of axis k put out early (chunks_early): the whole delta of the segment
 * `ahead` places from the queue's tail (1 while a segment runs at the tail, 0 between
 * segments), or 0 if there is none or that axis was not put out early. */
static int32_t chunk_out_early(uint8_t k, uint8_t ahead)
{
    if (k >= axes_ahead || (uint8_t)(plan_head - plan_tail) <= ahead)
        return 0;
    return plans[(uint8_t)(plan_tail + ahead) & (PLAN_SLOTS - 1)].delta[k];
}

/* A halt's engine axes (interrupts off, before the engine stops): the steps the engine
 * issued, not the profile's estimate (which put a halted stream one step off). Every
 * chunk out is a whole segment's delta: the running segment's engine axes, and the next
 * segment's axes put out early (chunks_early); stepper.pos holds the ended segments',
 * whose last edges may still be queued. The edges not raised yet are taken off. */
static void __attribute__((noinline)) engine_issued(struct seg_snapshot *sn)
{
    uint8_t ahead = sn->running ? 1 : 0;
    for (uint8_t k = 0; k < 4; k++) {
        int32_t out = chunk_out_early(k, ahead);
        if (sn->running && (sn->engine >> k & 1)) {
            out += sn->delta[k];
            sn->delta[k] = 0; /* counted here: seg_positions leaves it */
        }
        sn->pos[k] += out - step_engine_unissued(k);
    }
}

/* Whether a segment that has ended (its last tick computed: it is counted done, its
 * record row will say so) still has edges the engine has not raised. Between segments
 * each stepper holds what is left of the ended segment and, for the axes put out early,
 * the next segment's whole chunk. Interrupts off. */
static uint8_t ended_edges_left(void)
{
    if (stepper.current == IT_SEG)
        return 0;
    for (uint8_t k = 0; k < 4; k++)
        if (step_engine_unissued(k) != chunk_out_early(k, 0))
            return 1;
    return 0;
}

/* A halt between segments lets the ended segment's last edges out first, as the
 * tick's wheel does for the tick it computed (the default build): the engine would drop
 * them, and the segment counted done would end a few steps short (an underrun, which
 * comes at the ended segment's last tick, always did: its record row said "done" with
 * 3-5 steps missing, and a resume after it started from a position the record did not
 * hold). A segment's end is at most its last tick away, two tick starts or so;
 * stepper.running is already 0, so no segment starts meanwhile. Interrupts on (the
 * main loop's halt); with them off the edges are dropped and counted as before. */
static void __attribute__((noinline)) let_ended_segment_out(void)
{
    if (!(SREG & _BV(SREG_I)))
        return;
    uint8_t since = tick_gen;
    for (;;) {
        cli();
        uint8_t left = ended_edges_left();
        sei();
        if (!left || (uint8_t)(tick_gen - since) > 3)
            return;
    }
}
#endif

void stepper_halt(void)
{
    struct seg_snapshot sn;
#if STEP_ENGINE
    stepper.running = 0;
    let_ended_segment_out();
#endif
    uint8_t s = SREG;
    cli();
    seg_snapshot(&sn);
    if (stepper.current == IT_SEG) {
        abort_pending = 1;
        abort_seq = stepper.seg_next;
    }
    stepper.current = 0xFF;
    stepper.at_rest = 1;
    stepper.running = 0;
#if STEP_ENGINE
    engine_issued(&sn);
#endif
    if (STEP_ENGINE)
        step_engine_stop();
    if (STEP_ENGINE)
        chunks_ahead = axes_ahead = 0;
    SREG = s;
    if (sn.running || STEP_ENGINE) { /* (the engine's edges counted even between segments) */
        /* in place (seg_positions reads each axis's start before it writes it): the
         * shutdown path is the stack's deepest, 16 B of a second array are its margin */
        seg_positions(&sn, sn.pos);
        cli();
        for (uint8_t k = 0; k < 4; k++)
            stepper.pos[k] = sn.pos[k];
        SREG = s;
    }
}

void stepper_resume(void)
{
    stepper.running = 1;
}

void stepper_flush(uint32_t items_received, uint32_t segments_received)
{
    uint8_t s = SREG;
    cli();
    queue_tail = queue_head;
    if (STEP_ENGINE)
        step_engine_stop();
    if (STEP_ENGINE) {
        chunks_ahead = axes_ahead = 0;
        blocks_reset();
        blk_held = 0;
    }
    stepper.items_done = items_received;
    stepper.seg_next = segments_received + 1;
    main_changes++;
    motion_plans_reset();
    SREG = s;
}

void stepper_disable_all(void)
{
    uint8_t s = SREG;
    cli();
    stepper.enabled_mask = 0;
    stepper.homed_mask = 0;
    main_changes++;
    apply_enables(0);
    SREG = s;
}

/* ---------------------------------------------------------------- the next tick */

static void complete_item(void)
{
    stepper.items_done++;
    queue_tail++;
}

static void __attribute__((noinline)) set_pos_marker(void)
{
    SIM_POSITIONS(stepper.pos);
    next_tick->flags |= OUT_POS;
    settle_ticks = 2;
}

/* One homing step: the modules of `stepping` move one step (toward negative those of
 * `backing`), their pulses at the tick's start. */
static void __attribute__((noinline)) home_step(uint8_t stepping, uint8_t backing)
{
    next_tick->dir = (uint8_t)((cur_dir & 0x8) | backing);
    next_tick->own = 0x0F;
    int32_t *pos = ((struct stepper_state *)&stepper)->pos; /* private to this interrupt here */
    for (uint8_t k = 0; k < 3; k++)
        if (stepping >> k & 1)
            pos[k] += (backing >> k & 1) ? -1 : 1;
    if (stepping) {
        next_tick->ev[0].mask = stepping;
        next_tick->ev[0].at = 0;
        next_tick->ev[1].mask = 0;
        next_tick->n = 1;
    }
}

#if STEP_ENGINE
_Static_assert(sizeof(struct axis_plan) == STEP_STEADY_STRIDE, "the engine reads the plan's intervals");
#endif


#if STEP_ENGINE
/* seg_chunks' axes of `rest` (bit k: stepper k) that go through step_engine_push: a
 * block's, a steady one the one pass could not place */
static void __attribute__((noinline)) push_rest(const struct plan *p, uint32_t start,
                                                uint8_t rest)
{
    struct step_chunk c;
    const struct axis_plan *x = p->ax;
    const int32_t *d = p->delta;
    const struct sched_chunk *h = &block_chunks[p->blk_at];
    uint8_t blk = p->blk_mask;
    for (uint8_t j = 0; j < 4; j++, x++, d++, blk >>= 1, rest >>= 1) {
        const struct sched_chunk *own = h;
        if (blk & 1)
            h += 1 + h->count; /* the axis's header and chunks */
        if (!(rest & 1))
            continue;
        int32_t n = *d;
        c.neg = n < 0;
        if (!(blk & 1)) {
            c.interval = x->interval;
            c.t = start + (c.interval >> 1);
            c.count = (uint16_t)(n < 0 ? -n : n);
            c.add = 0;
            c.nblk = 0;
        } else {
            c.t = start + own->interval; /* the header's: the first edge */
            c.nblk = (uint8_t)(own->count - 1);
            c.blk = own + 2;
            own++;
            c.count = own->count;
            c.interval = own->interval & 0x7FFFFFFFUL; /* (the assembly's mark off) */
            c.add = own->add;
        }
        if (!step_engine_push(j, &c))
            /* (no slot: the motion stops where it is rather than go on without the axis's
             * steps, its position counted as if they were made) */
            raise_error(ERR_PLANNER_LATE, stepper.items_done, stepper.segments_done, j, 0);
    }
}
#endif

/* The step engine's axes of a segment: from the segment's start `start` (Q24.8 on the
 * steppers' clock), a steady axis one chunk (its first edge half an interval in,
 * PROTOCOL.md 5.1), an axis with a schedule block its block's chunks (the first one
 * here, the engine reads the others from the ring as it goes); the axes from `from` on,
 * at most `most` moving ones. The steady ones go out in one pass (the common case: every
 * axis); returns the axis after the last one chosen (4: all) and, in the high byte, the
 * axes left to push_rest: a block's, a steady one the pass could not place. */
static uint16_t __attribute__((noinline, unused)) seg_steady(const struct plan *p, uint32_t start,
                                                             uint8_t from, uint8_t most)
{
#if STEP_ENGINE
    uint8_t chosen = 0, k = from;
    if (!from && most >= 4) {
        chosen = PLAN_ENGINE(p);
        k = 4;
    } else {
        for (; k < 4 && most; k++)
            if (PLAN_ENGINE(p) & bit_of[k]) {
                chosen |= bit_of[k];
                most--;
            }
    }
    uint8_t steady = (uint8_t)(chosen & ~p->blk_mask), rest = chosen;
    if (steady)
        rest &= (uint8_t)(~steady | step_engine_push_steadies(start, steady,
                                                              (const uint8_t *)&p->ax[0].interval,
                                                              p->delta));
    return (uint16_t)rest << 8 | k;
#else
    (void)p;
    (void)start;
    (void)from;
    (void)most;
    return 4;
#endif
}

/* (inline: the two calls one frame deep from the caller, not two) */
static inline __attribute__((always_inline)) uint8_t seg_chunks(const struct plan *p, uint32_t start,
                                                                uint8_t from, uint8_t most)
{
    uint16_t r = seg_steady(p, start, from, most);
#if STEP_ENGINE
    if (r >> 8)
        push_rest(p, start, (uint8_t)(r >> 8));
#endif
    return (uint8_t)r;
}

#if STEP_ENGINE
/* An axis the tick's DDA drives in the tick now ending (a ramp without its block) that
 * reverses: the DDA keeps it for segment p too (the engine would set its direction pin
 * now, under the DDA's last steps). One planned without the DDA's constants (motion.c:
 * the high nibble of blk_mask) never is (its plan saw the DDA's last tick): if it were,
 * stop rather than step it wrong (0). */
static uint8_t __attribute__((noinline)) hand_back(struct plan *p)
{
    uint8_t flip = this_tick->own & p->engine & (uint8_t)(p->dir ^ cur_dir);
    if (flip & (p->blk_mask >> 4)) {
        raise_error(ERR_PLANNER_LATE, stepper.items_done, stepper.segments_done, 0xFF, 0);
        return 0;
    }
    p->engine &= (uint8_t)~flip;
    return 1;
}
#endif

/* Start queue items until a timed one runs (or nothing may start); at most a
 * few instantaneous items per tick, so a queue of them cannot stretch a tick. */
static void __attribute__((noinline)) dispatch(void)
{
    uint8_t budget = 4;
    while (queue_head != queue_tail && stepper.current == 0xFF && !settle_ticks && stepper.running && budget--) {
        struct item *it = queue_slot(queue_tail);
        switch (it->kind) {
        case IT_SEG: {
            /* (a start from rest whose chunks are going out goes on: they run at their
             * time, the segment must start with them) */
#if STEP_ENGINE
            if (stepper.at_rest && stepper_start_for != queue_tail && !chunks_ahead && !axes_ahead)
                return;
#else
            if (stepper.at_rest && !stepper_start_ok)
                return;
#endif
            struct plan *p = &plans[plan_tail & (PLAN_SLOTS - 1)];
            if (plan_tail == plan_head || p->index != queue_tail) {
                if (!stepper.at_rest) {
                        /* the main loop did not prepare it in time: the motion would stretch,
                     * so stop and say so (not a step-rate excess: PLANNER_LATE) */
                    stepper_plan_stalls++;
                    raise_error(ERR_PLANNER_LATE, stepper.items_done, stepper.segments_done, 0xFF,
                                TICK_UNITS);
                }
                return;
            }
            seg_plan = p;
            if ((stepper.enabled_mask | p->moving) != stepper.enabled_mask) {
                stepper.enabled_mask |= p->moving;
                apply_enables(stepper.enabled_mask);
            }
            if (STEP_ENGINE && stepper.at_rest && !chunks_ahead && p->moving &&
                PLAN_ENGINE(p) == p->moving) {
                /* from rest, every axis the step engine's: its chunks go out in two idle
                 * ticks, two axes in each, and the segment starts after them. Starting a
                 * stepper from rest costs about 1,000 cycles: all four with the segment's
                 * first tick took up to 6,370 of the 6,400 cycles of the tick that
                 * computed it (an overrun in some runs, the motion's marker missed) */
                uint8_t later = axes_ahead ? 1 : 2; /* ticks to the segment's start */
                axes_ahead = seg_chunks(
                    p, step_clock_next_tick + ((uint32_t)(later * TICK_CYCLES) << STEP_FRAC_BITS),
                    axes_ahead, 2);
                if (later == 1) /* (the second tick, whatever the first put out) */
                    chunks_ahead = 1;
                return;
            }
            ticks_left = p->ticks;
            stepper.current = IT_SEG;
#if STEP_ENGINE
            if (this_tick->own && !hand_back(p))
                return;
#endif
            if (STEP_ENGINE && PLAN_ENGINE(p)) {
                if (chunks_ahead)
                    chunks_ahead = 0;
                else
                    seg_chunks(p, step_clock_next_tick, 0, 4);
                axes_ahead = 0;
            }
            return;
        }
        case IT_DWELL:
            stepper.at_rest = 1;
            ticks_left = motion_ticks_of(it->ticks, &last_units);
            stepper.current = IT_DWELL;
            return;
        case IT_HOME:
            if (budget != 3)
                return; /* first in its tick: the homing computation must not overrun the
                         * tick (its start edge would be lost) */
            stepper.at_rest = 1;
            homing_start(it->flags & 7);
            stepper.enabled_mask |= it->flags & 7;
            apply_enables(stepper.enabled_mask);
            stepper.current = IT_HOME;
            return;
        case IT_WAIT:
            stepper.wait_heater = it->u.cmd.id;
            stepper.wait_tolerance = it->u.cmd.value;
            /* fall through */
        case IT_TUNE: /* the main loop runs it (autotune.c) */
            stepper.at_rest = 1;
            stepper_wait_ok = 0;
            stepper.current = it->kind;
            return;
        case IT_SETPOS:
            for (uint8_t k = 0; k < 4; k++)
                stepper.pos[k] = it->u.pos[k];
            set_pos_marker();
            break;
        case IT_ENABLE:
            stepper.enabled_mask = it->u.cmd.mask & 0x0F;
            apply_enables(stepper.enabled_mask);
            break;
        case IT_HEATER:
            heater_targets[it->u.cmd.id] = it->u.cmd.value;
            heater_targets_changed |= (uint8_t)(1 << it->u.cmd.id);
            break;
        case IT_FAN:
            pwm_set_fan((uint8_t)it->u.cmd.value);
            break;
        }
        complete_item();
        if (!stepper.at_rest && queue_head == queue_tail)
            raise_error(ERR_UNDERRUN, stepper.items_done, stepper.segments_done, 0xFF, 0);
    }
}

/* Steps one axis issues in a tick that is not the segment's last: (v += a),
 * acc += v; the steps are the change of acc's top byte. 36 cycles, 72 with
 * the acceleration (in assembly: half what the compiler makes of the C). */
static inline __attribute__((always_inline)) uint8_t dda_tick(struct axis_plan *x, uint8_t accel)
{
    uint8_t n;
    __asm__ volatile(
        "ldd r20, Z+2\n\t"
        "ldd r21, Z+3\n\t"
        "ldd r22, Z+4\n\t"
        "ldd r23, Z+5\n\t"
        "tst %[accel]\n\t"
        "breq 2f\n\t"
        "ldd r18, Z+0\n\t"
        "ldd r19, Z+1\n\t"
        "ldd __tmp_reg__, Z+6\n\t"
        "add r18, __tmp_reg__\n\t"
        "ldd __tmp_reg__, Z+7\n\t"
        "adc r19, __tmp_reg__\n\t"
        "ldd __tmp_reg__, Z+8\n\t"
        "adc r20, __tmp_reg__\n\t"
        "ldd __tmp_reg__, Z+9\n\t"
        "adc r21, __tmp_reg__\n\t"
        "ldd __tmp_reg__, Z+10\n\t"
        "adc r22, __tmp_reg__\n\t"
        "ldd __tmp_reg__, Z+11\n\t"
        "adc r23, __tmp_reg__\n\t"
        "brpl 1f\n\t" /* v < 0 only by rounding at the end of a stop: 0 */
        "clr r18\n\t"
        "clr r19\n\t"
        "clr r20\n\t"
        "clr r21\n\t"
        "clr r22\n\t"
        "clr r23\n"
        "1:\n\t"
        "std Z+0, r18\n\t"
        "std Z+1, r19\n\t"
        "std Z+2, r20\n\t"
        "std Z+3, r21\n\t"
        "std Z+4, r22\n\t"
        "std Z+5, r23\n"
        "2:\n\t"
        "ldd r18, Z+12\n\t"
        "ldd r19, Z+13\n\t"
        "ldd r24, Z+14\n\t"
        "ldd r25, Z+15\n\t"
        "mov %[n], r25\n\t"
        "add r18, r20\n\t"
        "adc r19, r21\n\t"
        "adc r24, r22\n\t"
        "adc r25, r23\n\t"
        "std Z+12, r18\n\t"
        "std Z+13, r19\n\t"
        "std Z+14, r24\n\t"
        "std Z+15, r25\n\t"
        "sub r25, %[n]\n\t"
        "mov %[n], r25\n\t"
        : [n] "=&r"(n)
        : "z"(x), [accel] "r"(accel)
        : "r18", "r19", "r20", "r21", "r22", "r23", "r24", "r25", "memory");
    return n;
}

/* With the step engine: the next segment's chunks put out during this one, one moving
 * axis in each of its last AXES_AHEAD_TICKS ticks but the last, and what is left with
 * the last (whose end is the next one's start), so each stepper takes its chunk at its
 * last edge of this segment without stopping, and no tick does the whole boundary's work
 * (with three steppers at 33K the steppers leave a tick about a third of the CPU, and
 * the segment's end and the four chunks together overran it). Only a steady segment
 * after a steady one, that dispatch would start as it is (its plan ready, its axes
 * enabled, nothing to wait for); else dispatch does it (after a ramp, whose last steps
 * the tick's wheel issues, an early start of the steppers put the ramp's last step
 * 135 us late). `ahead`: the plans between the running one and the next (1 during the
 * segment, 0 in its last tick, after plan_tail moved on); `to_end`: the cycles from the
 * start of the tick being computed to the segment's end; `most`: the moving axes to put
 * out now. */
#define AXES_AHEAD_TICKS 4
static void chunks_early(uint16_t to_end, uint8_t tail, uint8_t ahead, uint8_t most)
{
    if (!STEP_ENGINE || settle_ticks || (uint8_t)(plan_head - plan_tail) <= ahead ||
        queue_slot(tail)->kind != IT_SEG)
        return;
    const struct plan *n = &plans[(uint8_t)(plan_tail + ahead) & (PLAN_SLOTS - 1)];
    if (n->index != tail || !n->moving || PLAN_ENGINE(n) != n->moving ||
        (stepper.enabled_mask | n->moving) != stepper.enabled_mask)
        return; /* (a segment that moves no axis: nothing out, nothing marked out, or the
                 * next moving one would take the mark and put out none of its own) */
    axes_ahead = seg_chunks(n, step_clock_next_tick + ((uint32_t)to_end << STEP_FRAC_BITS),
                            axes_ahead, most);
    if (!ahead)
        chunks_ahead = 1;
}
_Static_assert(AXES_AHEAD_TICKS * TICK_CYCLES + 2 * TICK_CYCLES < 0x10000UL, "to_end in 16 bits");

/* The last tick of a segment whose steps the tick's wheel places: each axis issues what
 * is left (the exact total), and the positions move by what was issued. */
static void __attribute__((noinline)) last_steps(struct plan *p, int32_t *pos)
{
    uint16_t span = (uint16_t)(p->last_units * UNIT_CYCLES);
    uint8_t last = LAST_SLOT(p->last_units); /* once, not per axis (a 6-bit shift loop) */
    const struct axis_plan *x = p->ax;
    /* the axes the wheel steps; the positions, every axis's, after them (two short loops
     * keep their pointers in registers: one loop spilled them, 15 % of its time) */
    for (uint8_t k = 0, m = p->moving & (uint8_t)~PLAN_ENGINE(p); m; k++, x++, m >>= 1) {
        if (!(m & 1))
            continue;
        /* N minus what was issued: the estimate's difference to the DDA */
        int8_t off = (int8_t)(uint8_t)((uint8_t)(x->acc >> 24) - x->est_low);
        uint32_t rem = x->last_n - (int32_t)off;
        if (!rem)
            continue;
        uint8_t n = (uint8_t)rem;
        if (rem > AX_MAX) {
            /* more than a tick holds (never at the advertised rate): the position counts
             * only the steps issued */
            uint32_t lost = rem - AX_MAX;
            stepper_lost_steps += (uint16_t)lost;
            pos[k] += p->delta[k] < 0 ? (int32_t)lost : -(int32_t)lost;
            n = AX_MAX;
        }
        uint32_t frac = x->acc & 0xFFFFFFUL;
        if (p->accel)
            /* the mean rate over what is left, bent by the segment's acceleration */
            lost_count(place_axis(k, n, frac, ((uint32_t)n << 24) + 0x800000UL - frac, span,
                                  last, bend_of(x->a_hi)));
        else if (x->period)
            /* at the rate of the axis's last tick with steps (a steady segment's) */
            place_steps(bit_of[k], n, (uint16_t)(frac >> 8), x->period, last);
        else
            /* no rate known yet: over the distance left, from the last crossing to
             * N + 1/2, which the accumulator (N p + 1/2) reaches at the end */
            lost_count(place_axis(k, n, frac, ((uint32_t)n << 24) + 0x800000UL - frac, span,
                                  last, 0));
    }
    const int32_t *d = p->delta;
    for (uint8_t k = 0; k < 4; k++)
        pos[k] += d[k];
}

/* A segment ends (its last tick, starting at step_clock_next_tick and next_tick->units
 * long, is being computed): its block is held until the time its tick ends. */
static void blocks_done(const struct plan *p)
{
#if !STEP_ENGINE
    (void)p;
#else
    if (!(p->blk_mask & 0x0F) || blk_held == BLK_HELD)
        return; /* (full: never; the next block's release frees it) */
    uint16_t span = (uint16_t)(next_tick->units * UNIT_CYCLES);
    blk_fifo[blk_held].end = step_clock_next_tick + ((uint32_t)span << STEP_FRAC_BITS);
    blk_fifo[blk_held].blk_end = p->blk_end;
    blk_held++;
#endif
}

/* The held blocks whose segments' ends have passed (the tick in progress began after
 * them) are freed; all of them once the steppers stopped. */
static void __attribute__((noinline)) blocks_expire(uint8_t idle)
{
    uint8_t n = 0;
    while (n < blk_held && (idle || (int32_t)(step_clock_this_tick - blk_fifo[n].end) >= 0))
        n++;
    if (!n)
        return;
    blocks_release(blk_fifo[n - 1].blk_end);
    for (uint8_t i = n; i < blk_held; i++)
        blk_fifo[i - n] = blk_fifo[i];
    blk_held = (uint8_t)(blk_held - n);
}

/* The segment's last tick: its last steps, its end. */
static void __attribute__((noinline)) seg_last_tick(struct plan *p)
{
    struct stepper_state *s = (struct stepper_state *)&stepper; /* private to this interrupt here */
    struct out *o = next_tick;
    if (STEP_ENGINE && PLAN_ENGINE(p) == p->moving) {
        /* the step engine's chunks issue every step (the whole delta): no count to check,
         * and this tick stays short (at 3 x 33K the steppers leave it a third of the CPU;
         * the DDA path's bookkeeping, 500 instructions for nothing here, overran it) */
        const int32_t *d = p->delta;
        int32_t *pos = s->pos;
        for (uint8_t k = 0; k < 4; k++)
            pos[k] += d[k];
        if (occ_lo <= occ_hi) /* (no axis of the tick's wheel: empty, its events cleared) */
            lost_count(wheel_take(o));
    } else {
        last_steps(p, s->pos);
        lost_count(wheel_take(o));
    }
    if (STEP_ENGINE)
        blocks_done(p);
    s->current = 0xFF;
    o->flags |= OUT_SEG_END;
    o->seq = s->segments_done = s->seg_next++;
    s->at_rest = p->at_rest;
    plan_tail++;
    s->items_done++;
    uint8_t tail = ++queue_tail;
    if (!p->at_rest && queue_head == tail)
        raise_error(ERR_UNDERRUN, s->items_done, s->segments_done, 0xFF, 0);
    else if (STEP_ENGINE && !p->at_rest && PLAN_ENGINE(p) == p->moving && axes_ahead < 4)
        chunks_early((uint16_t)(o->units * UNIT_CYCLES), tail, 0, 4);
    else if (STEP_ENGINE && !p->at_rest && PLAN_ENGINE(p) == p->moving)
        chunks_ahead = 1; /* every axis went out during the segment */
}

/* A limit switch stops the segment: ENDSTOP_HIT (the main loop adds the position). */
static void __attribute__((noinline)) limit_hit(const struct plan *p)
{
    int8_t k = limits_check(p->moving, p->dir);
    if (k < 0)
        return;
    raise_error(ERR_ENDSTOP_HIT, stepper.items_done + 1, stepper.segments_done + 1, (uint8_t)k,
                0);
    if (STEP_ENGINE) {
        /* the step engine's chunks stop with the tick, not when the main loop halts: this
         * segment's and the next one's, out during its last ticks (chunks_early) */
        step_engine_stop();
        chunks_ahead = axes_ahead = 0;
    }
}

/* A tick of a segment whose steps are all the step engine's, no limit switch pressed:
 * the tick keeps only the segment clock, so it takes the segment's next ticks with it,
 * LONG_TICKS at most, and its fixed cost (the interrupt's entry and exit, the chores,
 * the computation: about 750 cycles) comes once in that time instead of once every
 * 400 us.
 *
 * A segment of LONG_END_TICKS or more (a steady one of 10 ms: 9 tick interrupts, not 25)
 * takes long ticks only far from its end: its last ticks stay 400 us as in any
 * segment, AXES_AHEAD_TICKS + 1 of them before the next segment (each of the first four
 * puts out one axis's chunk of it, chunks_early; the last ends the segment on its exact
 * clock unit), two before rest (the main loop sees the motion ended once the last one is
 * computed, at the start of the one before: the host then takes the device for idle).
 * Merged into a long last tick, a 10 ms segment's end (with all four chunks in one
 * interrupt) was computed 2 ms earlier, and the device's FLOW report with it, whose bytes
 * then went out across the boundary where the three modules' chunks start together: at
 * 3 x 33K + E the boundary's first edges came 10-27 us late.
 *
 * A shorter segment (a ramp's piece, 1-4 ms) would keep next to no long tick that way:
 * its end is merged into a long last tick on its exact clock unit when what is left fits
 * one tick (a byte of units) and this is not the segment's first tick (computed with
 * the end of the segment before: the steppers then hold the chunks of one segment ahead,
 * not two), with the next segment's chunks (chunks_early in seg_last_tick); else the
 * next tick is left to end it, about as long as this one (the end's work, the next
 * piece's block chunks, then has a long tick beside the steppers: 400 us ticks overran
 * at the braking's start). A limit switch pressed during a long tick is seen at the next
 * one (the ticks are 400 us again from then on). Returns LONG_NONE (the tick stays a
 * 400 us one, ticks_left as it was), LONG_TICK, or LONG_END (this tick ends the segment:
 * the caller computes its end, seg_last_tick, from a frame less deep). */
enum { LONG_NONE, LONG_TICK, LONG_END };
#define LONG_TICKS 6
#define LONG_END_TICKS (2 * (AXES_AHEAD_TICKS + 1))
/* a long tick's units in a byte, a merged last one's too (LONG_TICKS - 2 ticks and the
 * segment's last, up to 79 units) */
_Static_assert(LONG_TICKS * TICK_UNITS <= 255, "a long tick in a byte");
_Static_assert((LONG_TICKS - 2) * TICK_UNITS + 2 * TICK_UNITS - 1 <= 255, "a last one in a byte");
static uint8_t __attribute__((noinline)) long_tick(const struct plan *p, struct out *o)
{
    uint32_t left = ticks_left; /* ticks after this one (>= 1), the last one included */
    uint8_t more = LONG_TICKS - 1;
    if (p->at_rest || p->ticks >= LONG_END_TICKS) {
        uint8_t keep = p->at_rest ? 2 : AXES_AHEAD_TICKS + 1; /* the end's 400 us ticks */
        if (left <= keep)
            return LONG_NONE;
        if (left - keep < more)
            more = (uint8_t)(left - keep);
    } else if (left < LONG_TICKS && left + 1 != p->ticks &&
               (uint16_t)((uint8_t)left * TICK_UNITS + p->last_units) <= 255) {
        /* this one and the rest: (left) whole ticks and the last (40-79 units) */
        o->units = (uint8_t)((uint8_t)left * TICK_UNITS + p->last_units);
        ticks_left = 0;
        return LONG_END;
    } else if (left <= 2 * LONG_TICKS - 1) {
        /* the next tick to end the segment, about as long as this one */
        uint8_t last = (uint8_t)((uint8_t)(left - 1) / 2); /* the next tick's whole ticks */
        if (last > LONG_TICKS - 2)
            last = LONG_TICKS - 2;
        more = (uint8_t)((uint8_t)left - last - 1);
        if (more > LONG_TICKS - 1)
            more = LONG_TICKS - 1;
    }
    ticks_left = left - more;
    o->units = (uint8_t)((uint8_t)(more + 1) * TICK_UNITS);
    return LONG_TICK;
}

static void __attribute__((noinline)) seg_tick(void)
{
    struct plan *p = seg_plan;
    struct out *o = next_tick;
    uint8_t limits = limits_active();
    if (limits) {
        limit_hit(p);
        if (!stepper.running)
            return;
    }
    o->flags |= OUT_MOTION;
    o->dir = p->dir;
    if (STEP_ENGINE)
        o->own = p->moving & (uint8_t)~PLAN_ENGINE(p); /* the engine's axes set their own */
    if (--ticks_left == 0) {
        o->units = p->last_units;
        seg_last_tick(p);
        return;
    }
    uint8_t moving = p->moving, accel = p->accel, any = 0;
    if (STEP_ENGINE && PLAN_ENGINE(p) == moving) {
        /* every step is the step engine's: this tick only keeps the segment clock, and
         * far from the end takes the next ticks with it (long_tick); the last ticks put
         * out the next segment's chunks */
        uint8_t t = limits ? LONG_NONE : long_tick(p, o);
        if (t == LONG_END)
            seg_last_tick(p);
        if (t != LONG_NONE)
            return;
        if (ticks_left <= AXES_AHEAD_TICKS && !p->at_rest)
            chunks_early((uint16_t)((uint16_t)ticks_left * TICK_CYCLES +
                                    (uint16_t)(p->last_units * UNIT_CYCLES)),
                         (uint8_t)(queue_tail + 1), 1, 1);
        return;
    }
    struct axis_plan *x = p->ax;
    const uint8_t *bit = bit_of;
    for (uint8_t m = moving & (uint8_t)~PLAN_ENGINE(p); m; m >>= 1, x++, bit++) {
        if (!(m & 1))
            continue;
        /* before the tick: how far past its last crossing the axis is (Q0.16, the
         * accumulator's bits 8..23) */
        uint16_t f16 = *(const uint16_t *)((const uint8_t *)&x->acc + 1);
        uint8_t n = dda_tick(x, accel);
        if (!n)
            continue;
        any = 1;
        /* the tick moved the axis v_hi (Q8.24, after the acceleration's add): a steady
         * segment's rate was found with its plan, an accelerating one's changes */
        uint16_t c = x->period;
        if (accel)
            x->period = c = step_period((uint32_t)x->v_hi, TICK_CYCLES);
        if (n > AX_MAX) {
            stepper_lost_steps += (uint16_t)(n - AX_MAX); /* never at the advertised rate */
            n = AX_MAX;
        }
        if (!c)
            place_slow(*bit, (uint32_t)f16 << 8, (uint32_t)x->v_hi, TICK_CYCLES,
                       LAST_SLOT(TICK_UNITS), accel ? bend_of(x->a_hi) : 0);
        else if (accel)
            place_steps_bent(*bit, n, f16, c, LAST_SLOT(TICK_UNITS), bend_of(x->a_hi),
                             TICK_CYCLES);
        else
            place_steps(*bit, n, f16, c, LAST_SLOT(TICK_UNITS));
    }
    if (any)
        lost_count(wheel_take(o));
}

/* A homing tick: a step, a wait between steps, or the end (positions set, HOMED to
 * report) or a failure. */
static void __attribute__((noinline)) home_tick(struct out *o)
{
    uint8_t stepping = 0, backing = 0, homing = homing_tick(&stepping, &backing);
    if (homing == HOMING_DONE) {
        const struct item *it = queue_slot(queue_tail);
        uint8_t mask = it->flags & 7;
        for (uint8_t k = 0; k < 3; k++)
            if (mask >> k & 1)
                stepper.pos[k] = it->u.pos[k];
        stepper.homed_mask |= mask;
        stepper_report.homed_item = stepper.items_done + 1;
        stepper_report.homed = 1;
        stepper.current = 0xFF;
        complete_item();
        set_pos_marker();
    } else if (homing == HOMING_FAILED) {
        raise_error(ERR_HOMING_FAILED, stepper.items_done + 1, 0, 0xFF,
                    (int32_t)homing_steps());
        stepper.current = 0xFF;
    } else {
        if (homing == HOMING_STEP)
            home_step(stepping, backing);
        o->flags |= OUT_MOTION;
        o->units = HOME_TICK_UNITS;
    }
}

/* Everything but a segment's tick. */
static void __attribute__((noinline)) compute_other(void)
{
    struct out *o = next_tick;
    {
        if (abort_pending) {
            abort_pending = 0;
            o->flags = OUT_SEG_END | OUT_ABORT;
            o->seq = abort_seq;
            return;
        }
        if (settle_ticks) {
            settle_ticks--;
            return;
        }
        if (stepper.current == 0xFF)
            dispatch();
        if (stepper.current == 0xFF || !stepper.running)
            return;
        switch (stepper.current) {
        case IT_SEG:
            seg_tick();
            break;
        case IT_DWELL:
            o->flags |= OUT_MOTION;
            if (--ticks_left == 0) {
                o->units = last_units;
                stepper.current = 0xFF;
                complete_item();
            }
            break;
        case IT_HOME:
            home_tick(o);
            break;
        case IT_WAIT:
        case IT_TUNE:
            if (stepper_wait_ok) {
                stepper.current = 0xFF;
                complete_item();
            }
            break;
        }
    }
}

void __attribute__((noinline)) stepper_compute(void)
{
    struct out *o = next_tick;
    o->n = 0;
    o->ev[0].mask = 0;
    o->flags = 0;
    o->dir = cur_dir;
    o->own = STEP_ENGINE ? 0 : 0x0F;
    o->units = TICK_UNITS;
    if (STEP_ENGINE && blk_held)
        blocks_expire(stepper.current != IT_SEG && step_engine_idle());
    if (stepper.current == IT_SEG && stepper.running)
        seg_tick(); /* the common case first */
    else if (stepper.current != 0xFF || queue_head != queue_tail || abort_pending || settle_ticks)
        compute_other(); /* else idle */
    if (o->flags & OUT_MOTION)
        stepper.motion_ticks += o->units;
}

/* What a tick's start does that needs no exact time: the markers, the scheduler's
 * clock, the heater lease. With interrupts on (compare B may nest: nothing here
 * touches its pins or its data). */
void __attribute__((noinline)) stepper_tick_chores(void)
{
    struct out *e = this_tick;
    /* MARK_EDGE toggles when this tick ends if it ends a segment (the harness reads the
     * segment's number at that edge); motion_marker may add a start or stop of motion
     * to that boundary */
    markers_tick_start(e, &stepper.motion_ticks); /* through this tick (computed) */
    sched_clock_advance(e->units);
    heater_lease_tick();
    if (STEP_ENGINE)
        /* a long tick (long_tick) counts as the 400 us ticks it holds */
        for (uint8_t u = e->units; u >= 2 * TICK_UNITS; u = (uint8_t)(u - TICK_UNITS))
            heater_lease_tick();
}
