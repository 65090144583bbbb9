/* The step interrupt: Timer1 in CTC mode, one compare match per tick.
 *
 * Ticks are TICK_UNITS clock units long, except the last tick of a segment or
 * dwell, which is as long as the item needs (OCR1A is rewritten at the start of
 * the tick whose length differs), so items start and end on exact clock units.
 * Work is pipelined one tick deep: at a tick's start the interrupt first marks
 * what the tick that just ended completed (segment end, positions set, abort),
 * then sets this tick's directions, all computed during the previous interrupt.
 * Each step has its own time: the DDA counts a tick's steps per axis and places
 * each at the time the segment's profile gives it (interpolated inside the tick
 * from the accumulator and the axis's cycles per step), on a time wheel of
 * SLOT_CYCLES slots; the axes that fall in one slot form one event, and compare B
 * issues the events at their times. Then, with its own interrupt masked and the
 * others allowed (so compare B keeps its time), it computes the next tick.
 *
 * Pulses are high for at least 2 us and a direction change leads the next pulse
 * by at least 1 us (A4988: 1 us / 200 ns, DRV8825: 1.9 us / 650 ns, TMC2208:
 * 0.1 us / 20 ns). A pulse issued later than LATE_TOLERANCE_US after its time is
 * counted (HEALTH late_pulses) and the worst lateness kept. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/pgmspace.h>

#include "board_ramps14.h"
#include "config.h"
#include "sim_hooks.h"
#include "mul16.h"
#include "step_pins.h"
#include "step_events.h"
#include "step_rate.h"
#include "step_wheel.h"
#include "motion.h"
#include "protocol_gen.h"
#include "queue.h"
#include "sched.h"
#include "stepper.h"

volatile uint32_t sched_clock_count;
volatile struct stepper_state st;
volatile struct stepper_report stepper_report;
volatile uint8_t stepper_start_ok, stepper_wait_ok;
volatile uint8_t heater_duty[2], fan_duty;
volatile uint16_t heater_lease;
volatile uint16_t stepper_isr_max_cycles;
volatile uint16_t stepper_lost_steps, stepper_plan_stalls, stepper_overruns, stepper_late_pulses;
volatile uint8_t stepper_latency_max;
volatile uint16_t stepper_late_worst;
volatile uint32_t stepper_late_tolerance;
static volatile uint8_t computing, tick_missed;
/* bumped by every tick interrupt: the main loop's snapshots retry until none came
 * between their first and last read, instead of masking interrupts for 20 us */
static volatile uint8_t tick_gen;
static uint8_t handed_over; /* the next tick's first event went out with this one's */
/* the axes of a pending compare B event that compare A's entry raised */
static volatile uint8_t prepulsed __attribute__((used));

#define OUT_MOTION 0x01
#define OUT_SEG_END 0x02
#define OUT_POS 0x04
#define OUT_ABORT 0x08

/* OCR1C: toggle MARK_EDGE (OC1C) a few cycles into the next tick (simavr only
 * arms a compare whose time has not passed when its timer period starts, and
 * that start may be seen a few cycles late); above TOP: never */
#define EDGE_AT_NEXT_TICK 8
#define EDGE_NEVER 0xFFFF
#define HOME_TICKS (CLOCK_HZ / ((uint32_t)DEV_HOMING_RATE * HOME_TICK_UNITS))
_Static_assert(HOME_TICKS * DEV_HOMING_RATE * HOME_TICK_UNITS == CLOCK_HZ,
               "a homing step must take a whole number of homing ticks");

static struct out outs[2];
static struct out *emit = &outs[0]; /* the tick being emitted */
static struct out *nx = &outs[1];   /* the tick being computed */
static uint8_t cur_dir = 0xFF, ocr_units = TICK_UNITS;

/* steps the wheel had no room for (never at the advertised rate): counted, not lost
 * silently */
static inline __attribute__((always_inline)) void lost_count(uint8_t lost)
{
    if (lost)
        stepper_lost_steps += lost;
}

/* the executing item */
static struct plan *run;    /* SEG */
static uint32_t t_left;     /* SEG, DWELL: ticks left */
static uint8_t last_units;  /* DWELL: length of the last tick */
static uint8_t hold;          /* ticks to wait after positions were set */
static uint8_t abort_pending; /* a segment was abandoned: mark it */
static uint32_t abort_seq;
static uint8_t home_mask, home_backoff, home_div;
static uint32_t home_steps;
static uint8_t pwm;

void stepper_init(uint8_t hold_mask)
{
    X_STEP_DDR |= _BV(X_STEP_BIT); X_DIR_DDR |= _BV(X_DIR_BIT); X_EN_DDR |= _BV(X_EN_BIT);
    Y_STEP_DDR |= _BV(Y_STEP_BIT); Y_DIR_DDR |= _BV(Y_DIR_BIT); Y_EN_DDR |= _BV(Y_EN_BIT);
    Z_STEP_DDR |= _BV(Z_STEP_BIT); Z_DIR_DDR |= _BV(Z_DIR_BIT); Z_EN_DDR |= _BV(Z_EN_BIT);
    E_STEP_DDR |= _BV(E_STEP_BIT); E_DIR_DDR |= _BV(E_DIR_BIT); E_EN_DDR |= _BV(E_EN_BIT);
    st.enabled_mask = hold_mask & 0x0F;
    apply_enables(st.enabled_mask);
    X_MIN_DDR &= (uint8_t)~_BV(X_MIN_BIT); X_MIN_PORT |= _BV(X_MIN_BIT);
    Y_MIN_DDR &= (uint8_t)~_BV(Y_MIN_BIT); Y_MIN_PORT |= _BV(Y_MIN_BIT);
    Z_MIN_DDR &= (uint8_t)~_BV(Z_MIN_BIT); Z_MIN_PORT |= _BV(Z_MIN_BIT);
    X_MAX_DDR &= (uint8_t)~_BV(X_MAX_BIT); X_MAX_PORT |= _BV(X_MAX_BIT);
    Y_MAX_DDR &= (uint8_t)~_BV(Y_MAX_BIT); Y_MAX_PORT |= _BV(Y_MAX_BIT);
    Z_MAX_DDR &= (uint8_t)~_BV(Z_MAX_BIT); Z_MAX_PORT |= _BV(Z_MAX_BIT);
    if (SIM_HOOKS) { /* the simulator's markers: the board build leaves D4, D6, D13 alone */
        MARK_EDGE_DDR |= _BV(MARK_EDGE_BIT);
        MARK_POS_DDR |= _BV(MARK_POS_BIT);
        MARK_ABORT_DDR |= _BV(MARK_ABORT_BIT);
    }
    FAN_DDR |= _BV(FAN_BIT);
    st.current = 0xFF;
    st.at_rest = 1;
    st.running = 1;
    st.seg_next = 1;
    outs[0].units = outs[1].units = TICK_UNITS;
    /* Timer1: CTC on OCR1A, no prescaler; in the simulator build compare C toggles OC1C
     * (MARK_EDGE) when OCR1C is set to match one cycle into the next tick */
    TCCR1A = SIM_HOOKS ? _BV(COM1C0) : 0;
    TCCR1B = _BV(WGM12) | _BV(CS10);
    OCR1A = TICK_CYCLES - 1;
    OCR1C = EDGE_NEVER;
    TIMSK1 = _BV(OCIE1A);
}

void stepper_counts(uint32_t *items, uint32_t *segments)
{
    uint8_t s = SREG;
    cli();
    *items = st.items_done;
    *segments = st.segments_done;
    SREG = s;
}

uint32_t stepper_ticks_left(void)
{
    return (st.current == IT_SEG || st.current == IT_DWELL) ? t_left : 0;
}

uint8_t stepper_moving(void)
{
    return st.current != 0xFF || !st.at_rest;
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
    st.running = 0;
}

/* What the positions mid-segment are made of, taken with interrupts off. */
struct seg_snapshot {
    int32_t pos[4];
    uint8_t running; /* a segment is executing */
    uint8_t acc_int[4];
    uint32_t done_ticks;
    float ka, kb;
    int32_t delta[4];
};

static void seg_snapshot(struct seg_snapshot *sn)
{
    for (uint8_t k = 0; k < 4; k++)
        sn->pos[k] = st.pos[k];
    sn->running = st.current == IT_SEG;
    if (!sn->running)
        return;
    sn->done_ticks = run->ticks - t_left;
    sn->ka = run->ka;
    sn->kb = run->kb;
    for (uint8_t k = 0; k < 4; k++) {
        sn->acc_int[k] = (uint8_t)(run->ax[k].acc >> 24);
        sn->delta[k] = run->delta[k];
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
        int32_t issued = (int32_t)est + (int8_t)(uint8_t)(sn->acc_int[k] - (uint8_t)est);
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

void stepper_halt(void)
{
    struct seg_snapshot sn;
    uint8_t s = SREG;
    cli();
    seg_snapshot(&sn);
    if (st.current == IT_SEG) {
        abort_pending = 1;
        abort_seq = st.seg_next;
    }
    st.current = 0xFF;
    st.at_rest = 1;
    st.running = 0;
    SREG = s;
    if (sn.running) {
        int32_t pos[4];
        seg_positions(&sn, pos);
        cli();
        for (uint8_t k = 0; k < 4; k++)
            st.pos[k] = pos[k];
        SREG = s;
    }
}

void stepper_resume(void)
{
    st.running = 1;
}

void stepper_flush(uint32_t items_received, uint32_t segments_received)
{
    uint8_t s = SREG;
    cli();
    queue_tail = queue_head;
    st.items_done = items_received;
    st.seg_next = segments_received + 1;
    motion_plans_reset();
    SREG = s;
}

void stepper_disable_all(void)
{
    uint8_t s = SREG;
    cli();
    st.enabled_mask = 0;
    st.homed_mask = 0;
    apply_enables(0);
    SREG = s;
}

/* ---------------------------------------------------------------- the next tick */

static void complete_item(void)
{
    st.items_done++;
    queue_tail++;
}

static void __attribute__((noinline)) set_pos_marker(void)
{
    SIM_POSITIONS(st.pos);
    nx->flags |= OUT_POS;
    hold = 2;
}

static void start_homing(const struct item *it)
{
    home_mask = it->flags & 7;
    home_backoff = endstops() & home_mask;
    home_div = 0;
    home_steps = 0;
    st.enabled_mask |= home_mask;
    apply_enables(st.enabled_mask);
}

/* One homing tick: every HOME_TICKS ticks each module still homing checks its
 * switch and steps (away from a pressed switch until it releases, then toward
 * it until it closes). Returns 1 when all switches closed, so homing from d
 * steps takes d / DEV_HOMING_RATE seconds exactly, as in the Python model. */
static uint8_t __attribute__((noinline)) home_tick(void)
{
    if (home_div) {
        home_div--;
        return 0;
    }
    home_div = HOME_TICKS - 1;
    uint8_t stepping = 0, neg = 0, pressed = endstops();
    for (uint8_t k = 0; k < 3; k++) {
        uint8_t bit = (uint8_t)(1 << k);
        if (!(home_mask & bit))
            continue;
        uint8_t hit = pressed & bit;
        if (home_backoff & bit) {
            if (hit) {
                stepping |= bit;
                neg |= bit;
                continue;
            }
            home_backoff &= (uint8_t)~bit; /* released: approach again */
        }
        if (hit)
            home_mask &= (uint8_t)~bit;
        else
            stepping |= bit;
    }
    if (!home_mask)
        return 1;
    if (++home_steps > (uint32_t)DEV_HOMING_MAX_STEPS) {
        raise_error(ERR_HOMING_FAILED, st.items_done + 1, 0, 0xFF, (int32_t)home_steps);
        st.current = 0xFF;
        return 0;
    }
    nx->dir = (uint8_t)((cur_dir & 0x8) | neg);
    int32_t *pos = ((struct stepper_state *)&st)->pos; /* private to this interrupt here */
    for (uint8_t k = 0; k < 3; k++)
        if (stepping >> k & 1)
            pos[k] += (neg >> k & 1) ? -1 : 1;
    if (stepping) {
        nx->ev[0].mask = stepping;
        nx->ev[0].at = 0;
        nx->ev[1].mask = 0;
        nx->n = 1;
    }
    return 0;
}

/* Start queue items until a timed one runs (or nothing may start); at most a
 * few instantaneous items per tick, so a queue of them cannot stretch a tick. */
static void __attribute__((noinline)) dispatch(void)
{
    uint8_t budget = 4;
    while (queue_head != queue_tail && st.current == 0xFF && !hold && st.running && budget--) {
        struct item *it = queue_slot(queue_tail);
        switch (it->kind) {
        case IT_SEG: {
            if (st.at_rest && !stepper_start_ok)
                return;
            struct plan *p = &plans[plan_tail & (PLAN_SLOTS - 1)];
            if (plan_tail == plan_head || p->index != queue_tail) {
                if (!st.at_rest) {
                        /* the main loop did not prepare it in time: the motion would stretch,
                     * so stop and say so (not a step-rate excess: PLANNER_LATE) */
                    stepper_plan_stalls++;
                    raise_error(ERR_PLANNER_LATE, st.items_done, st.segments_done, 0xFF,
                                TICK_UNITS);
                }
                return;
            }
            run = p;
            if ((st.enabled_mask | p->moving) != st.enabled_mask) {
                st.enabled_mask |= p->moving;
                apply_enables(st.enabled_mask);
            }
            t_left = p->ticks;
            st.current = IT_SEG;
            return;
        }
        case IT_DWELL:
            st.at_rest = 1;
            t_left = motion_ticks_of(it->ticks, &last_units);
            st.current = IT_DWELL;
            return;
        case IT_HOME:
            if (budget != 3)
                return; /* first in its tick: the homing computation must not overrun the
                         * tick (its start edge would be lost) */
            st.at_rest = 1;
            start_homing(it);
            st.current = IT_HOME;
            return;
        case IT_WAIT:
            st.wait_heater = it->u.cmd.id;
            st.wait_tolerance = it->u.cmd.value;
            /* fall through */
        case IT_TUNE: /* the main loop runs it (autotune.c) */
            st.at_rest = 1;
            stepper_wait_ok = 0;
            st.current = it->kind;
            return;
        case IT_SETPOS:
            for (uint8_t k = 0; k < 4; k++)
                st.pos[k] = it->u.pos[k];
            set_pos_marker();
            break;
        case IT_ENABLE:
            st.enabled_mask = it->u.cmd.mask & 0x0F;
            apply_enables(st.enabled_mask);
            break;
        case IT_HEATER:
            st.heater_target[it->u.cmd.id] = it->u.cmd.value;
            st.heater_target_changed |= (uint8_t)(1 << it->u.cmd.id);
            break;
        case IT_FAN:
            st.fan = (uint8_t)it->u.cmd.value;
            fan_duty = st.fan;
            break;
        }
        complete_item();
        if (!st.at_rest && queue_head == queue_tail)
            raise_error(ERR_UNDERRUN, st.items_done, st.segments_done, 0xFF, 0);
    }
}

/* Steps one axis issues in a tick that is not the segment's last: (v += a),
 * acc += v; the steps are the change of acc's top byte. 36 cycles, 72 with
 * the acceleration (hand-written: the compiler's version took twice that). */
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

/* The segment's last tick: each axis issues what is left (the exact total). */
static void __attribute__((noinline)) seg_last_tick(struct plan *p)
{
    uint16_t span = (uint16_t)(p->last_units * UNIT_CYCLES);
    struct stepper_state *s = (struct stepper_state *)&st; /* private to this interrupt here */
    struct out *o = nx;
    struct axis_plan *x = p->ax;
    int32_t *pos = s->pos;
    const int32_t *d = p->delta;
    for (uint8_t k = 0; k < 4; k++, x++, pos++, d++) {
        if (!(p->moving >> k & 1))
            continue;
        /* N minus what was issued: the estimate's difference to the DDA */
        int8_t off = (int8_t)(uint8_t)((uint8_t)(x->acc >> 24) - x->est_low);
        uint32_t rem = x->last_n - (int32_t)off;
        int32_t moved = *d;
        if (rem) {
            uint8_t n = rem > AX_MAX ? AX_MAX : (uint8_t)rem;
            if (rem > AX_MAX) {
                /* more than a tick holds (never at the advertised rate): the position
                 * counts only the steps issued */
                uint32_t lost = rem - AX_MAX;
                stepper_lost_steps += (uint16_t)lost;
                moved += moved < 0 ? (int32_t)lost : -(int32_t)lost;
            }
            uint32_t frac = x->acc & 0xFFFFFFUL;
            if (p->accel)
                /* the mean rate over what is left, bent by the segment's acceleration */
                lost_count(place_axis(k, n, frac, ((uint32_t)n << 24) + 0x800000UL - frac, span,
                           LAST_SLOT(p->last_units), bend_of(x->a_hi)));
            else if (x->period)
                /* at the rate of the axis's last tick with steps (a steady segment's) */
                place_steps(bit_of[k], n, (uint16_t)(frac >> 8), x->period,
                            LAST_SLOT(p->last_units));
            else
                /* no rate known yet: over the distance left, from the last crossing to
                 * N + 1/2, which the accumulator (N p + 1/2) reaches at the end */
                lost_count(place_axis(k, n, frac, ((uint32_t)n << 24) + 0x800000UL - frac, span,
                           LAST_SLOT(p->last_units), 0));
        }
        *pos += moved;
    }
    lost_count(wheel_take(o));
    s->current = 0xFF;
    o->flags |= OUT_SEG_END;
    o->seq = s->segments_done = s->seg_next++;
    s->at_rest = p->at_rest;
    plan_tail++;
    s->items_done++;
    uint8_t tail = ++queue_tail;
    if (!p->at_rest && queue_head == tail)
        raise_error(ERR_UNDERRUN, s->items_done, s->segments_done, 0xFF, 0);
}

/* A limit switch pressed on two ticks in a row (debounced) while its module moves
 * toward it stops the motion: ENDSTOP_HIT (the main loop adds the position). */
static uint8_t limit_seen;

static void __attribute__((noinline)) limit_check(const struct plan *p)
{
    uint8_t hit = limits_pressed() & p->moving & (uint8_t)~p->dir & 7;
    uint8_t both = hit & limit_seen;
    limit_seen = hit;
    if (!both)
        return;
    uint8_t k = both & 1 ? 0 : both & 2 ? 1 : 2;
    raise_error(ERR_ENDSTOP_HIT, st.items_done + 1, st.segments_done + 1, k, 0);
}

static void __attribute__((noinline)) seg_tick(void)
{
    struct plan *p = run;
    struct out *o = nx;
    if (limits_pressed() | limit_seen) {
        limit_check(p);
        if (!st.running)
            return;
    }
    o->flags |= OUT_MOTION;
    o->dir = p->dir;
    if (--t_left == 0) {
        o->units = p->last_units;
        seg_last_tick(p);
        return;
    }
    uint8_t moving = p->moving, accel = p->accel, any = 0;
    struct axis_plan *x = p->ax;
    const uint8_t *bit = bit_of;
    for (uint8_t m = moving; m; m >>= 1, x++, bit++) {
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

/* Everything but a segment's tick. */
static void __attribute__((noinline)) compute_other(void)
{
    struct out *o = nx;
    {
        if (abort_pending) {
            abort_pending = 0;
            o->flags = OUT_SEG_END | OUT_ABORT;
            o->seq = abort_seq;
            return;
        }
        if (hold) {
            hold--;
            return;
        }
        if (st.current == 0xFF)
            dispatch();
        if (st.current == 0xFF || !st.running)
            return;
        switch (st.current) {
        case IT_SEG:
            seg_tick();
            break;
        case IT_DWELL:
            o->flags |= OUT_MOTION;
            if (--t_left == 0) {
                o->units = last_units;
                st.current = 0xFF;
                complete_item();
            }
            break;
        case IT_HOME:
            if (home_tick()) {
                const struct item *it = queue_slot(queue_tail);
                uint8_t mask = it->flags & 7;
                for (uint8_t k = 0; k < 3; k++)
                    if (mask >> k & 1)
                        st.pos[k] = it->u.pos[k];
                st.homed_mask |= mask;
                stepper_report.homed_item = st.items_done + 1;
                stepper_report.homed = 1;
                st.current = 0xFF;
                complete_item();
                set_pos_marker();
            } else if (st.current == IT_HOME) {
                o->flags |= OUT_MOTION;
                o->units = HOME_TICK_UNITS;
            }
            break;
        case IT_WAIT:
        case IT_TUNE:
            if (stepper_wait_ok) {
                st.current = 0xFF;
                complete_item();
            }
            break;
        }
    }
}

static void __attribute__((noinline)) compute(void)
{
    struct out *o = nx;
    o->n = 0;
    o->ev[0].mask = 0;
    o->flags = 0;
    o->dir = cur_dir;
    o->units = TICK_UNITS;
    if (st.current == IT_SEG && st.running)
        seg_tick(); /* the common case first */
    else if (st.current != 0xFF || queue_head != queue_tail || abort_pending || hold)
        compute_other(); /* else idle */
    if (o->flags & OUT_MOTION)
        st.motion_ticks += o->units;
}

/* ---------------------------------------------------------------- interrupts */


static uint16_t late; /* cycles of earlier ticks handled in this interrupt */
static uint8_t edge_armed; /* OCR1C set to toggle MARK_EDGE at the next boundary */

/* One step event now, from compare A (with interrupts off): its lateness noted as
 * compare B notes it, pulses 2 us high. */
static void __attribute__((noinline)) event_now(uint8_t m, uint16_t at, uint16_t now)
{
    pulse_on(m);
    uint16_t l = (int16_t)(now - at) > 0 ? (uint16_t)(now - at) : 0;
    if (l > stepper_late_worst)
        stepper_late_worst = l;
    if (l > LATE_TOLERANCE_CYCLES)
        stepper_late_tolerance++;
    __builtin_avr_delay_cycles(PULSE_CYCLES - 8);
    pulse_off();
}

/* Events of the tick that just ended that compare B has not issued yet (the tick
 * started so late that its events ran past its end): issued now, before the new
 * tick's, 2 us high and 2 us low each, so no step is lost; each is counted late.
 * With interrupts off. */
static void __attribute__((noinline)) flush_events(void)
{
    /* lateness: from the event's time in the tick that ended (its period) to now */
    uint16_t ended = (uint16_t)(ocr_units * UNIT_CYCLES);
    const struct event *e = stepper_next;
    if (prepulsed) {
        /* raised by compare A's entry: held high, then ended */
        uint16_t l = (uint16_t)(TCNT1 + ended - e->at);
        if (l > stepper_late_worst)
            stepper_late_worst = l;
        if (l > LATE_TOLERANCE_CYCLES) {
            stepper_late_pulses++;
            stepper_late_tolerance++;
        }
        prepulsed = 0;
        __builtin_avr_delay_cycles(PULSE_CYCLES);
        pulse_off();
        __builtin_avr_delay_cycles(PULSE_CYCLES);
        e++;
    }
    for (; e->mask; e++) {
        uint16_t l = (uint16_t)(TCNT1 + ended - e->at);
        pulse_on(e->mask);
        if (l > stepper_late_worst)
            stepper_late_worst = l;
        if (l > LATE_TOLERANCE_CYCLES) {
            stepper_late_pulses++;
            stepper_late_tolerance++;
        }
        __builtin_avr_delay_cycles(PULSE_CYCLES);
        pulse_off();
        __builtin_avr_delay_cycles(PULSE_CYCLES);
    }
    TIMSK1 &= (uint8_t)~_BV(OCIE1B);
    TIFR1 = _BV(OCF1B);
}

/* Events due within this many cycles are issued by compare A itself (it holds the
 * CPU until then); compare B is armed for the first one after. */
#define A_EARLY 48

/* The start of a tick, with interrupts off and as short as it can be: this tick's
 * length, directions, the events due at once, compare B armed for the rest. */
static void __attribute__((noinline)) tick_start(void)
{
    uint8_t entry = TCNT1L; /* cycles since the compare match (< 256 unless late) */
    if (TIMSK1 & _BV(OCIE1B))
        flush_events(); /* compare B disables itself after a tick's last event */
    struct out *e = nx;
    nx = emit;
    emit = e;
    struct event *ev = e->ev;
    if (handed_over) {
        ev++; /* issued by the last tick's compare B, just before this tick began */
        handed_over = 0;
    }
    if (e->dir != cur_dir) {
        /* first, and in a tick without steps too: a reversal's first step, at the next
         * tick's start, can then go out with this tick's compare B (hand_over_first) */
        apply_dirs(e->dir);
        cur_dir = e->dir;
        __builtin_avr_delay_cycles(16);
    }
    uint16_t high_from = 0;
    uint8_t first = 0;
    if (ev->mask && !late) {
        /* a first step due at once goes out before anything else (the bookkeeping
         * below runs while its pulse is high) */
        uint16_t at = ev->at;
        if ((int16_t)(at - TCNT1) < A_EARLY) {
            while ((int16_t)(TCNT1 - at) < 0)
                ;
            pulse_on(ev->mask);
            high_from = TCNT1;
            uint16_t l = (int16_t)(high_from - at) > 0 ? (uint16_t)(high_from - at) : 0;
            if (l > stepper_late_worst)
                stepper_late_worst = l;
            if (l > LATE_TOLERANCE_CYCLES)
                stepper_late_tolerance++;
            ev++;
            first = 1;
        }
    }
    uint8_t units = e->units;
    if (units != ocr_units) {
        ocr_units = units;
        uint16_t top = (uint16_t)(units * UNIT_CYCLES - 1);
        OCR1A = top;
        uint16_t now = TCNT1;
        if ((uint16_t)(now + 8) > top) {
            /* this (shorter) tick is over already: its compare match would be missed
             * and the timer run on to 0xFFFF (a 4 ms hole). Wrap the period by hand,
             * keeping the time base, and start the next tick at once (late). */
            TCNT1 = (uint16_t)(now - top + 1);
            tick_missed = 1;
        }
    }
    if (entry > stepper_latency_max && !late)
        stepper_latency_max = entry;
    if (first) {
        while ((uint16_t)(TCNT1 - high_from) < PULSE_CYCLES)
            ;
        pulse_off();
        __builtin_avr_delay_cycles(PULSE_CYCLES); /* low before another pulse */
    }
    if (!ev->mask)
        return;
    for (; ev->mask; ev++) {
        /* (a tick started late runs in its own timer period all the same: its later
         * steps keep their time) */
        uint16_t at = ev->at, now = TCNT1;
        if ((int16_t)(at - now) <= 0) {
            event_now(ev->mask, at, now);
        } else if (at - now < A_EARLY) {
            while ((int16_t)(TCNT1 - at) < 0)
                ;
            event_now(ev->mask, at, at);
        } else {
            break;
        }
        __builtin_avr_delay_cycles(PULSE_CYCLES); /* low before another pulse */
    }
    stepper_next = ev;
    if (ev->mask) {
        OCR1B = ev->at;
        TIFR1 = _BV(OCF1B); /* a match earlier in this tick left its flag */
        TIMSK1 |= _BV(OCIE1B);
    }
}

/* What a tick's start does that needs no exact time: markers, the scheduler's clock,
 * the heater lease and the PWM outputs. With interrupts on (compare B may nest:
 * nothing here touches its pins or its data). */
static void __attribute__((noinline)) tick_chores(void)
{
    struct out *e = emit;
    uint8_t f = e->flags;
    if (SIM_HOOKS && (f & (OUT_POS | OUT_ABORT))) {
        /* positions were set (at rest); a segment was abandoned (before the
         * edge that ends it) */
        if (f & OUT_ABORT)
            MARK_ABORT_PIN = _BV(MARK_ABORT_BIT);
        if (f & OUT_POS)
            MARK_POS_PIN = _BV(MARK_POS_BIT);
    }
    /* MARK_EDGE toggles when this tick ends if it ends a segment (the harness
     * reads the segment's number at that edge); motion_marker may add a start
     * or stop of motion to that boundary */
    if (f & OUT_SEG_END) {
        sim_segment_end(e->seq, &st.motion_ticks); /* through this tick (computed) */
        edge_armed = 1;
        OCR1C = EDGE_AT_NEXT_TICK;
    } else if (edge_armed) {
        edge_armed = 0;
        OCR1C = EDGE_NEVER;
    }
    sched_clock_count += e->units;
    uint8_t p = ++pwm;
    if (heater_lease)
        heater_lease--;
    else
        heater_duty[0] = heater_duty[1] = 0; /* the control loop stopped refreshing them */
    if (p < heater_duty[0]) HOTEND_PORT |= _BV(HOTEND_BIT); else HOTEND_PORT &= (uint8_t)~_BV(HOTEND_BIT);
    if (p < heater_duty[1]) BED_PORT |= _BV(BED_BIT); else BED_PORT &= (uint8_t)~_BV(BED_BIT);
    if (p < fan_duty) FAN_PORT |= _BV(FAN_BIT); else FAN_PORT &= (uint8_t)~_BV(FAN_BIT);
}

/* Motion starts or stops at the next tick boundary: MARK_EDGE toggles there
 * (armed just after the next tick's computation, before that boundary). */
static void __attribute__((noinline)) motion_marker(void)
{
    uint8_t next = nx->flags & OUT_MOTION;
    if (next == (emit->flags & OUT_MOTION))
        return;
    sim_motion_edge(edge_armed, next);
    edge_armed = 1;
    OCR1C = EDGE_AT_NEXT_TICK;
}

/* After a tick's computation: the interrupt's length so far, and whether the
 * next tick has already begun (returns 1: start it now). */
static uint8_t __attribute__((noinline)) tick_end(void)
{
    uint16_t used = TCNT1 + late;
    if (tick_missed) {
        tick_missed = 0;
        stepper_overruns++;
        used += (uint16_t)(ocr_units * UNIT_CYCLES);
        late += (uint16_t)(ocr_units * UNIT_CYCLES);
    } else {
        late = 0;
    }
    if (used > stepper_isr_max_cycles)
        stepper_isr_max_cycles = used;
    return late != 0;
}

/* The computation runs with interrupts on, so compare B keeps its phases'
 * time. Should it overrun into the next tick, that tick's interrupt only
 * notes it and this one starts the tick at once (late), as silicon would
 * (without masking compare A: simavr 1.6 never queues an interrupt that was
 * enabled after its flag rose). Nothing lives across the calls, so the entry
 * saves only what a call clobbers. */
/* The tick's tail runs with interrupts off (~130 cycles to its return): a compare B
 * event due in that time goes out first, unless it is so close to the tick's end
 * that waiting for it would run the tail into the next tick. */
#define TAIL_CYCLES 144
static inline void tail_guard(void)
{
    uint16_t last = (uint16_t)(OCR1A - TAIL_CYCLES);
    while (TIMSK1 & _BV(OCIE1B)) {
        uint16_t b = OCR1B;
        if ((uint16_t)(b - TCNT1) >= TAIL_CYCLES || b > last)
            break;
    }
}

/* A step due in the first cycles of the next tick goes out from this tick's compare
 * B, HANDOVER_LEAD cycles before the boundary (its pulse rises about when the tick
 * begins), rather than from compare A once its entry has run (~130 cycles, 8 us,
 * late). Only when the next tick keeps the directions and this one ends on time. */
#define HANDOVER_LEAD 8
static void __attribute__((noinline)) hand_over_first(void)
{
    const struct event *f = nx->ev;
    uint8_t n = emit->n;
    if (!f->mask || f->at >= A_EARLY || nx->dir != cur_dir || n >= EV_MAX)
        return;
    uint16_t at = (uint16_t)(ocr_units * UNIT_CYCLES - 1 - HANDOVER_LEAD);
    if ((int16_t)(at - TCNT1) < 24)
        return; /* too close to arm compare B in time */
    struct event *e = &emit->ev[n];
    e->mask = f->mask;
    e->at = at;
    e[1].mask = 0;
    emit->n = (uint8_t)(n + 1);
    handed_over = 1;
    if (!(TIMSK1 & _BV(OCIE1B))) {
        stepper_next = e;
        OCR1B = at;
        TIFR1 = _BV(OCF1B);
        TIMSK1 |= _BV(OCIE1B);
    }
}
/* Compare A's entry, before the compiler's prologue (about 50 cycles): a compare B
 * event still pending at the boundary (another interrupt held compare B past it, and
 * compare A comes first) has its pulses raised at once; flush_events ends them. Then
 * the tick proper, a signal handler entered as if from the vector. */
void __vector_tick(void) __attribute__((signal, used));
ISR(TIMER1_COMPA_vect, ISR_NAKED)
{
    __asm__ volatile(
        "push r24\n\t"
        "in r24, __SREG__\n\t"
        "push r24\n\t"
        "lds r24, %[timsk]\n\t"
        "sbrs r24, %[ocieb]\n\t"
        "rjmp 1f\n\t"
        "lds r24, computing\n\t"
        "tst r24\n\t"
        "brne 1f\n\t" /* an overrun: the interrupted tick flushes */
        "push r30\n\t"
        "push r31\n\t"
        "lds r30, stepper_next\n\t"
        "lds r31, stepper_next+1\n\t"
        "ld r24, Z\n\t"
        "sts prepulsed, r24\n\t"
        STEP_PULSE_ASM("2")
        "pop r31\n\t"
        "pop r30\n"
        "1:\n\t"
        "pop r24\n\t"
        "out __SREG__, r24\n\t"
        "pop r24\n\t"
        "jmp __vector_tick\n\t"
        :
        : STEP_PULSE_ASM_OPERANDS, [timsk] "n"(_SFR_MEM_ADDR(TIMSK1)), [ocieb] "I"(OCIE1B));
}

void __vector_tick(void)
{
    tick_gen++;
    if (computing) {
        tick_missed = 1;
        return;
    }
    do {
        tick_start();
        computing = 1;
        sei();
        tick_chores();
        compute();
        tail_guard();
        cli();
        computing = 0;
        motion_marker();
    } while (tick_end());
    hand_over_first();
}
