/* Timer1 in CTC mode interrupts every tick. Work is pipelined one tick deep:
 * the interrupt first finishes what the previous tick's pulses mean for the
 * markers, then emits the step pulses computed during the previous interrupt
 * (direction first, then the first pulse of each axis; the second and third at
 * k/6 of the tick from compare B), then computes the next tick. Pulses
 * are high for at least 2 us and direction changes lead them by at least 1 us
 * (A4988: 1 us / 200 ns, DRV8825: 1.9 us / 650 ns, TMC2208: 0.1 us / 20 ns). */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <string.h>

#include "board_ramps14.h"
#include "config.h"
#include "mailbox.h"
#include "protocol_gen.h"
#include "queue.h"
#include "sched.h"
#include "stepper.h"

volatile uint32_t sched_tick_count;
volatile struct stepper_state st;
volatile struct stepper_report stepper_report;
volatile uint8_t stepper_start_ok, stepper_wait_ok;
volatile uint8_t heater_duty[2], fan_duty;
volatile uint16_t stepper_isr_max_cycles;
volatile uint16_t stepper_lost_steps;

#define OUT_MOTION 0x01
#define OUT_SEG_END 0x02
#define OUT_POS 0x04
#define OUT_ABORT 0x08
#define OUT_DIR 0x10

struct out {
    uint8_t m[MAX_STEPS_PER_TICK]; /* axes stepping in phase k of the tick */
    uint8_t flags;
    uint8_t dir; /* axis bit set: negative */
    uint32_t seq;
};
static struct out outs[2];
static uint8_t which;  /* outs[which] is being emitted, the other one computed */
#define emit (outs[which])
#define next (outs[which ^ 1])
static uint8_t phase;
static uint8_t cur_dir = 0xFF;

/* executing item: one DDA per axis */
struct axis {
    int32_t v, a;
    uint32_t acc, rem;
};
static struct axis ax[4];
static uint32_t t_left;
static uint8_t hold;          /* ticks to wait after positions were set */
static uint8_t abort_pending; /* a segment was abandoned: mark it */
static uint32_t abort_seq;
static uint8_t home_mask, home_backoff;
static uint16_t home_acc;
static uint32_t home_steps;
static uint8_t pwm;

/* step pins of an axis mask on the X/Y port (the Z and E pins have ports of their own) */
static const uint8_t xy_bits[4] = {0, _BV(X_STEP_BIT), _BV(Y_STEP_BIT), _BV(X_STEP_BIT) | _BV(Y_STEP_BIT)};

static inline void pulse_on(uint8_t m)
{
    X_STEP_PORT |= xy_bits[m & 3];
    if (m & 4)
        Z_STEP_PORT |= _BV(Z_STEP_BIT);
    if (m & 8)
        E_STEP_PORT |= _BV(E_STEP_BIT);
}

static inline void pulse_off(void)
{
    X_STEP_PORT &= (uint8_t)~(_BV(X_STEP_BIT) | _BV(Y_STEP_BIT));
    Z_STEP_PORT &= (uint8_t)~_BV(Z_STEP_BIT);
    E_STEP_PORT &= (uint8_t)~_BV(E_STEP_BIT);
}

static void apply_enables(uint8_t mask)
{
    /* active low */
    if (mask & 1) X_EN_PORT &= (uint8_t)~_BV(X_EN_BIT); else X_EN_PORT |= _BV(X_EN_BIT);
    if (mask & 2) Y_EN_PORT &= (uint8_t)~_BV(Y_EN_BIT); else Y_EN_PORT |= _BV(Y_EN_BIT);
    if (mask & 4) Z_EN_PORT &= (uint8_t)~_BV(Z_EN_BIT); else Z_EN_PORT |= _BV(Z_EN_BIT);
    if (mask & 8) E_EN_PORT &= (uint8_t)~_BV(E_EN_BIT); else E_EN_PORT |= _BV(E_EN_BIT);
}

static void apply_dirs(uint8_t neg)
{
    if (((neg >> 0) & 1) ^ X_DIR_INVERT) X_DIR_PORT &= (uint8_t)~_BV(X_DIR_BIT); else X_DIR_PORT |= _BV(X_DIR_BIT);
    if (((neg >> 1) & 1) ^ Y_DIR_INVERT) Y_DIR_PORT &= (uint8_t)~_BV(Y_DIR_BIT); else Y_DIR_PORT |= _BV(Y_DIR_BIT);
    if (((neg >> 2) & 1) ^ Z_DIR_INVERT) Z_DIR_PORT &= (uint8_t)~_BV(Z_DIR_BIT); else Z_DIR_PORT |= _BV(Z_DIR_BIT);
    if (((neg >> 3) & 1) ^ E_DIR_INVERT) E_DIR_PORT &= (uint8_t)~_BV(E_DIR_BIT); else E_DIR_PORT |= _BV(E_DIR_BIT);
}

static uint8_t endstop(uint8_t axis)
{
    uint8_t v;
    if (axis == 0)
        v = (X_MIN_PIN >> X_MIN_BIT) & 1;
    else if (axis == 1)
        v = (Y_MIN_PIN >> Y_MIN_BIT) & 1;
    else
        v = (Z_MIN_PIN >> Z_MIN_BIT) & 1;
    return v == ENDSTOP_TRIGGERED_LEVEL;
}

void stepper_init(void)
{
    X_STEP_DDR |= _BV(X_STEP_BIT); X_DIR_DDR |= _BV(X_DIR_BIT); X_EN_DDR |= _BV(X_EN_BIT);
    Y_STEP_DDR |= _BV(Y_STEP_BIT); Y_DIR_DDR |= _BV(Y_DIR_BIT); Y_EN_DDR |= _BV(Y_EN_BIT);
    Z_STEP_DDR |= _BV(Z_STEP_BIT); Z_DIR_DDR |= _BV(Z_DIR_BIT); Z_EN_DDR |= _BV(Z_EN_BIT);
    E_STEP_DDR |= _BV(E_STEP_BIT); E_DIR_DDR |= _BV(E_DIR_BIT); E_EN_DDR |= _BV(E_EN_BIT);
    apply_enables(0);
    X_MIN_DDR &= (uint8_t)~_BV(X_MIN_BIT); X_MIN_PORT |= _BV(X_MIN_BIT);
    Y_MIN_DDR &= (uint8_t)~_BV(Y_MIN_BIT); Y_MIN_PORT |= _BV(Y_MIN_BIT);
    Z_MIN_DDR &= (uint8_t)~_BV(Z_MIN_BIT); Z_MIN_PORT |= _BV(Z_MIN_BIT);
    MARK_DDR |= _BV(MARK_SEG_BIT);
    MARK2_DDR |= _BV(MARK_MOTION_BIT);
    MARK3_DDR |= _BV(MARK_POS_BIT);
    MARK4_DDR |= _BV(MARK_ABORT_BIT);
    FAN_DDR |= _BV(FAN_BIT);
    st.current = 0xFF;
    st.at_rest = 1;
    st.running = 1;
    /* Timer1: CTC on OCR1A, no prescaler */
    TCCR1A = 0;
    TCCR1B = _BV(WGM12) | _BV(CS10);
    OCR1A = TIMER_CYCLES_PER_TICK - 1;
    TIMSK1 = _BV(OCIE1A);
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

/* with interrupts off */
void stepper_halt(void)
{
    uint8_t s = SREG;
    cli();
    if (st.current == IT_SEG) {
        abort_pending = 1;
        abort_seq = st.segments_done + 1;
    }
    st.current = 0xFF;
    st.at_rest = 1;
    st.running = 0;
    SREG = s;
}

void stepper_resume(void)
{
    st.running = 1;
}

void stepper_flush(uint32_t items_received)
{
    uint8_t s = SREG;
    cli();
    queue_tail = queue_head;
    st.items_done = items_received;
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

static void complete_item(void)
{
    st.items_done++;
    queue_tail++;
}

static void set_pos_marker(void)
{
    for (uint8_t k = 0; k < 4; k++)
        sim_mailbox.pos[k] = st.pos[k];
    next.flags |= OUT_POS;
    hold = 2;
}

static void start_homing(struct item *it)
{
    home_mask = it->flags & 7;
    home_backoff = 0;
    for (uint8_t k = 0; k < 3; k++)
        if ((home_mask >> k & 1) && endstop(k))
            home_backoff |= (uint8_t)(1 << k);
    home_acc = TICK_HZ - DEV_HOMING_RATE; /* the first step on the first tick */
    home_steps = 0;
    st.enabled_mask |= home_mask;
    apply_enables(st.enabled_mask);
}

/* one homing tick; returns 1 when done */
static uint8_t home_tick(struct item *it)
{
    /* DEV_HOMING_RATE steps/s: step k on tick ceil(k TICK_HZ / rate) */
    home_acc += DEV_HOMING_RATE;
    if (home_acc < TICK_HZ)
        return 0;
    home_acc -= TICK_HZ;
    uint8_t stepping = 0, neg = 0;
    for (uint8_t k = 0; k < 3; k++) {
        uint8_t bit = (uint8_t)(1 << k);
        if (!(home_mask & bit))
            continue;
        uint8_t hit = endstop(k);
        if (home_backoff & bit) {
            if (!hit)
                home_backoff &= (uint8_t)~bit; /* released: approach again */
            else {
                stepping |= bit;
                neg |= bit;
                continue;
            }
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
    next.dir = (uint8_t)((cur_dir & 0x8) | neg);
    next.m[0] = stepping;
    for (uint8_t k = 0; k < 3; k++)
        if (stepping >> k & 1)
            st.pos[k] += (neg >> k & 1) ? -1 : 1;
    (void)it;
    return 0;
}

/* Start queue items until a timed one runs (or nothing may start). */
static void dispatch(void)
{
    while (queue_head != queue_tail && st.current == 0xFF && !hold && st.running) {
        struct item *it = queue_slot(queue_tail);
        switch (it->kind) {
        case IT_SEG:
            if (st.at_rest && !stepper_start_ok)
                return;
            for (uint8_t k = 0; k < 4; k++) {
                ax[k].v = it->u.seg.v0[k];
                ax[k].a = it->u.seg.a[k];
                ax[k].acc = 1UL << 23;
                ax[k].rem = it->u.seg.n[k];
                if (ax[k].rem)
                    st.enabled_mask |= (uint8_t)(1 << k);
            }
            apply_enables(st.enabled_mask);
            t_left = it->ticks;
            st.current = IT_SEG;
            return;
        case IT_DWELL:
            st.at_rest = 1;
            if (!it->ticks) {
                complete_item();
                continue;
            }
            t_left = it->ticks;
            st.current = IT_DWELL;
            return;
        case IT_HOME:
            st.at_rest = 1;
            start_homing(it);
            st.current = IT_HOME;
            return;
        case IT_WAIT:
            st.at_rest = 1;
            stepper_wait_ok = 0;
            st.wait_heater = it->u.cmd.id;
            st.wait_tolerance = it->u.cmd.value;
            st.current = IT_WAIT;
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

/* steps of one axis in this tick (at most MAX_STEPS_PER_TICK) */
static inline uint8_t axis_tick(struct axis *x, uint8_t last)
{
    uint32_t rem = x->rem;
    if (!rem)
        return 0;
    int32_t v = x->v;
    if (x->a) {
        v += x->a;
        if (v < 0)
            v = 0;
        x->v = v;
    }
    uint32_t acc = x->acc + (uint32_t)v;
    uint8_t n = (uint8_t)(acc >> 24);
    if (last)
        n = rem > 255 ? 255 : (uint8_t)rem;
    if (n > rem)
        n = (uint8_t)rem;
    if (n > MAX_STEPS_PER_TICK) {
        if (last)
            stepper_lost_steps += (uint8_t)(n - MAX_STEPS_PER_TICK);
        n = MAX_STEPS_PER_TICK;
    }
    x->acc = acc - ((uint32_t)n << 24);
    x->rem = rem - n;
    return n;
}

static void seg_tick(struct item *it)
{
    struct stepper_state *s = (struct stepper_state *)&st; /* private to this interrupt here */
    uint8_t last = --t_left == 0;
    uint8_t neg = it->flags >> 4;
    uint8_t m[MAX_STEPS_PER_TICK] = {0};
    next.flags |= OUT_MOTION;
    next.dir = neg;
    for (uint8_t k = 0, bit = 1; k < 4; k++, bit <<= 1) {
        uint8_t n = axis_tick(&ax[k], last);
        if (!n)
            continue;
        for (uint8_t i = 0; i < n; i++)
            m[i] |= bit;
        if (neg & bit)
            s->pos[k] -= n;
        else
            s->pos[k] += n;
    }
    for (uint8_t i = 0; i < MAX_STEPS_PER_TICK; i++)
        next.m[i] = m[i];
    if (last) {
        s->current = 0xFF;
        s->segments_done++;
        next.flags |= OUT_SEG_END;
        next.seq = s->segments_done;
        s->at_rest = it->flags & SEGF_AT_REST;
        complete_item();
        if (!s->at_rest && queue_head == queue_tail)
            raise_error(ERR_UNDERRUN, s->items_done, s->segments_done, 0xFF, 0);
    }
}

static void compute(void)
{
    struct out *o = &next;
    for (uint8_t i = 0; i < MAX_STEPS_PER_TICK; i++)
        o->m[i] = 0;
    o->flags = 0;
    o->dir = cur_dir;
    if (abort_pending) {
        abort_pending = 0;
        next.flags = OUT_SEG_END | OUT_ABORT;
        next.seq = abort_seq;
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
    struct item *it = queue_slot(queue_tail);
    switch (st.current) {
    case IT_SEG:
        st.motion_ticks++;
        seg_tick(it);
        break;
    case IT_DWELL:
        st.motion_ticks++;
        next.flags |= OUT_MOTION;
        if (--t_left == 0) {
            st.current = 0xFF;
            complete_item();
        }
        break;
    case IT_HOME:
        if (home_tick(it)) {
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
            st.motion_ticks++;
            next.flags |= OUT_MOTION;
        }
        break;
    case IT_WAIT:
        if (stepper_wait_ok) {
            st.current = 0xFF;
            complete_item();
        }
        break;
    }
}

ISR(TIMER1_COMPB_vect)
{
    uint8_t k = ++phase;
    if (k >= MAX_STEPS_PER_TICK) {
        TIMSK1 &= (uint8_t)~_BV(OCIE1B);
        return;
    }
    uint8_t t0 = TCNT1L;
    pulse_on(emit.m[k]);
    if (k + 1 < MAX_STEPS_PER_TICK && emit.m[k + 1])
        OCR1B = (uint16_t)((k + 1) * (TIMER_CYCLES_PER_TICK / MAX_STEPS_PER_TICK));
    else
        TIMSK1 &= (uint8_t)~_BV(OCIE1B);
    while ((uint8_t)(TCNT1L - t0) < 34)
        ;
    pulse_off();
}

ISR(TIMER1_COMPA_vect)
{
    /* markers for the pulses emitted during the tick that just ended */
    if (emit.flags & (OUT_SEG_END | OUT_POS | OUT_ABORT)) {
        sim_mailbox.seq = emit.seq;
        if (emit.flags & OUT_ABORT)
            MARK4_PIN = _BV(MARK_ABORT_BIT);
        if (emit.flags & OUT_SEG_END)
            MARK_PIN = _BV(MARK_SEG_BIT);
        if (emit.flags & OUT_POS)
            MARK3_PIN = _BV(MARK_POS_BIT);
    }
    which ^= 1;
    if (emit.flags & OUT_MOTION)
        MARK2_PORT |= _BV(MARK_MOTION_BIT);
    else
        MARK2_PORT &= (uint8_t)~_BV(MARK_MOTION_BIT);
    uint8_t pulses = emit.m[0];
    uint16_t t0 = TCNT1;
    if (pulses) {
        if (emit.dir != cur_dir) {
            apply_dirs(emit.dir);
            cur_dir = emit.dir;
            __builtin_avr_delay_cycles(16);
        }
        t0 = TCNT1;
        pulse_on(pulses);
        if (emit.m[1]) {
            phase = 0;
            OCR1B = TIMER_CYCLES_PER_TICK / MAX_STEPS_PER_TICK;
            TIFR1 = _BV(OCF1B);
            TIMSK1 |= _BV(OCIE1B);
        }
    }
    sched_tick_count++;

    compute();

    /* slow software PWM for the heaters and the fan (78 Hz) */
    uint8_t p = ++pwm;
    if (p < heater_duty[0]) HOTEND_PORT |= _BV(HOTEND_BIT); else HOTEND_PORT &= (uint8_t)~_BV(HOTEND_BIT);
    if (p < heater_duty[1]) BED_PORT |= _BV(BED_BIT); else BED_PORT &= (uint8_t)~_BV(BED_BIT);
    if (p < fan_duty) FAN_PORT |= _BV(FAN_BIT); else FAN_PORT &= (uint8_t)~_BV(FAN_BIT);

    if (pulses) {
        while ((uint16_t)(TCNT1 - t0) < 34)
            ;
        pulse_off();
    }
    /* cycles since the compare match (TCNT1 restarted from 0 there) */
    uint16_t used = TCNT1;
    if (TIFR1 & _BV(OCF1A))
        used += TIMER_CYCLES_PER_TICK; /* ran into the next tick */
    if (used > stepper_isr_max_cycles)
        stepper_isr_max_cycles = used;
}
