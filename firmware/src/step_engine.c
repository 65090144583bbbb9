/* The step engine (step_engine.h): the steppers' compare interrupts and their chunk
 * rings. */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <stddef.h>

#include "board_ramps14.h"
#include "config.h"
#include "schedule_block.h"
#include "step_engine.h"
#include "step_tick.h"

#if STEP_ENGINE /* config.h: off, its RAM is not spent */

/* A stepper's running state and its queued chunks. */
struct step_axis {
    uint32_t t;        /* the armed edge, Q24.8 */
    uint32_t interval; /* Q24.8 */
    uint16_t count;    /* edges of the running chunk left, the armed one included */
    uint8_t wraps;     /* whole timer periods to let pass before the armed compare */
    uint8_t slow;      /* the armed event is not the assembly's: wraps left, or an
                        * interval of 32,768 cycles or more (under 489 steps/s) */
    uint8_t running;   /* its compare interrupt is on */
    uint8_t spare;     /* (add is not 0: the stepper's bit k of GPIOR0, bit 4 + k its
                        * waiting chunk's is or it has a block: see GPIOR0_IO) */
    int32_t add;
    /* the running schedule block's chunks after the running one */
    uint8_t nblk;
    const struct sched_chunk *blk;
    /* The chunk after the running one, where the assembly takes it at the running one's
     * last edge (the ring's are C's): a segment's, put here a tick before it starts. */
    volatile uint8_t next_ready;
    struct step_chunk next;
    /* A steady chunk after that one, moved into next as the assembly takes next: with
     * segments shorter than two ticks the tick puts a segment's chunks out while the
     * segment before still waits in next (its flags: next_ready's). Set only while next
     * is: the ring's chunks come after both. */
    volatile uint8_t next2_ready;
    struct step_chunk next2;
    volatile uint8_t head, tail;
    struct step_chunk ring[CHUNK_SLOTS];
};
static struct step_axis axes[4];
/* the assembly reaches add, nblk and blk from running's address */
_Static_assert(offsetof(struct step_axis, spare) == offsetof(struct step_axis, running) + 1 &&
                   offsetof(struct step_axis, add) == offsetof(struct step_axis, running) + 2 &&
                   offsetof(struct step_axis, nblk) == offsetof(struct step_axis, running) + 6 &&
                   offsetof(struct step_axis, blk) == offsetof(struct step_axis, running) + 7 &&
                   offsetof(struct step_axis, next2_ready) ==
                       offsetof(struct step_axis, next) + 18 &&
                   offsetof(struct step_axis, next2) == offsetof(struct step_axis, next2_ready) + 1 &&
                   sizeof(struct step_chunk) == 18 &&
                   offsetof(struct step_chunk, add) == offsetof(struct step_chunk, neg) + 1 &&
                   offsetof(struct step_chunk, nblk) == offsetof(struct step_chunk, neg) + 5 &&
                   offsetof(struct step_chunk, blk) == offsetof(struct step_chunk, neg) + 6,
               "the assembly's offsets");
/* a block's chunk: count, interval, add (schedule_block.h), bit 31 of the interval set
 * where the assembly may not run it (step_blocks.c) */
_Static_assert(offsetof(struct sched_chunk, interval) == 2 && offsetof(struct sched_chunk, add) == 6 &&
                   sizeof(struct sched_chunk) == 10,
               "the assembly reads a block's chunks");
/* GPIOR0 (sbic/sbi reach it): bit k, stepper k's running chunk has an add; bit 4 + k,
 * its waiting chunk (next_*) has an add or further chunks (a block's) */
#define GPIOR0_IO "0x1E"

uint32_t step_clock_next_tick, step_clock_this_tick;
volatile uint16_t step_engine_late;
/* The steppers whose armed compare is an edge (running, no timer period left to wait), at
 * their flags' bits in TIFR3 (X, Y, Z: bits 1-3) and E at bit 4: another one's interrupt
 * may raise their pin (RAISE_PENDING below) */
uint8_t step_fast;

/* cycles from a compare match to the pulse's rising edge in the interrupt (its response,
 * the vector's jump, the prologue): the compare is set that much early */
#define ISR_LEAD 11
/* an edge armed closer to now than this is set this far ahead (late) */
#define ARM_MARGIN 24
/* the same in C (its compare write lands later) */
#define C_ARM_MARGIN 64
/* the assembly takes a waiting chunk whose first edge is under NEXT_FAR * 256 cycles after
 * the running chunk's last edge (with its lateness test's 16-bit times, up to 32,511 of
 * the 32,768 cycles it can tell ahead from past); C takes a farther one */
#define NEXT_FAR "0x7E" /* (a string: the assembly's operands are at their limit) */
/* next_ready's bits: a chunk waits; its direction is the running chunk's (the assembly
 * then leaves the pin and cur_dir alone at the take: 3 cycles instead of 13-16). Where
 * every stepper takes its next chunk at once (a segment's boundary, three modules in
 * step) the last one's first edge waits for the others' takes: with X's and Y's takes
 * shorter, module 3's first edge at a boundary is 2-3 us less late (7.2-7.8 us worst in
 * 3 x 33K + E instead of 9.5-10.5). (Setting a bit for the far check below at the push
 * instead, 14 cycles a take less, cost the tick 20-40 cycles in the segment's last ticks:
 * 57-95 tick overruns in a run.) */
#define NEXT_READY 1
#define NEXT_ADD 2 /* (next's chunk has an add or a block's further chunks: bit 4 + k) */
#define NEXT_SAME_DIR 4
#define NEXT2 8 /* a steady chunk waits in next2 too (next then never NEXT_SAME_DIR or NEXT_ADD) */

#define OCR_OF(t) ((uint16_t)(cycles_of((t) + (1UL << (STEP_FRAC_BITS - 1))) - ISR_LEAD))

/* Q24.8 <-> whole cycles by moving bytes (avr-gcc -Os makes a loop of a 32-bit shift by
 * 8, about 60 cycles: start_axis runs with interrupts off) */
static inline __attribute__((always_inline)) uint32_t cycles_of(uint32_t q)
{
    union { uint32_t u; uint8_t b[4]; } x = {q}, y;
    y.b[0] = x.b[1];
    y.b[1] = x.b[2];
    y.b[2] = x.b[3];
    y.b[3] = 0;
    return y.u;
}
static inline __attribute__((always_inline)) uint32_t q_of(uint16_t cycles)
{
    union { uint32_t u; uint8_t b[4]; } y;
    y.b[0] = 0;
    y.b[1] = (uint8_t)cycles;
    y.b[2] = (uint8_t)(cycles >> 8);
    y.b[3] = 0;
    return y.u;
}
_Static_assert(STEP_FRAC_BITS == 8, "cycles_of and q_of move whole bytes");
/* bit k (a variable shift is a loop too) */
static const uint8_t bit_of_k[4] = {1, 2, 4, 8};
static inline __attribute__((always_inline)) uint8_t has_add(uint8_t k)
{
    return GPIOR0 & bit_of_k[k];
}

void step_engine_start_timers(uint8_t timer1_b)
{
    TCCR3A = 0;
    TCCR5A = 0;
    TCCR3B = 0;
    TCCR5B = 0;
    TCNT3 = 0;
    TCNT5 = 0;
    /* Timer5, Timer3 and Timer1 started two cycles apart: Timer3's count leads Timer1's
     * by 2 and Timer5's by 4 (Timer5's is set right below) */
    __asm__ volatile("sts %[t5], %[cs]\n\t"
                     "sts %[t3], %[cs]\n\t"
                     "sts %[t1], %[b1]\n\t"
                     :
                     : [t5] "n"(_SFR_MEM_ADDR(TCCR5B)), [t3] "n"(_SFR_MEM_ADDR(TCCR3B)),
                       [t1] "n"(_SFR_MEM_ADDR(TCCR1B)), [cs] "r"((uint8_t)_BV(CS30)),
                       [b1] "r"(timer1_b));
    /* Timer1's first tick ends at its first compare match, TICK_CYCLES in */
    step_clock_this_tick = 2UL << STEP_FRAC_BITS;
    step_clock_next_tick = (TICK_CYCLES + 2UL) << STEP_FRAC_BITS;
    TIMSK3 = 0;
    TIMSK5 = 0;
}

/* The compare registers and enables of each stepper */
#define X_OCR OCR3A
#define Y_OCR OCR3B
#define Z_OCR OCR3C
#define E_OCR OCR5A

static inline __attribute__((always_inline)) void set_dir(uint8_t k, uint8_t neg)
{
    switch (k) {
    case 0:
        if (neg ^ X_DIR_INVERT) X_DIR_PORT &= (uint8_t)~_BV(X_DIR_BIT); else X_DIR_PORT |= _BV(X_DIR_BIT);
        break;
    case 1:
        if (neg ^ Y_DIR_INVERT) Y_DIR_PORT &= (uint8_t)~_BV(Y_DIR_BIT); else Y_DIR_PORT |= _BV(Y_DIR_BIT);
        break;
    case 2:
        if (neg ^ Z_DIR_INVERT) Z_DIR_PORT &= (uint8_t)~_BV(Z_DIR_BIT); else Z_DIR_PORT |= _BV(Z_DIR_BIT);
        break;
    default:
        if (neg ^ E_DIR_INVERT) E_DIR_PORT &= (uint8_t)~_BV(E_DIR_BIT); else E_DIR_PORT |= _BV(E_DIR_BIT);
        break;
    }
    if (neg)
        cur_dir |= bit_of_k[k];
    else
        cur_dir &= (uint8_t)~bit_of_k[k];
}

static inline __attribute__((always_inline)) volatile uint16_t *ocr_of(uint8_t k)
{
    return k == 0 ? &X_OCR : k == 1 ? &Y_OCR : k == 2 ? &Z_OCR : &E_OCR;
}
static inline __attribute__((always_inline)) volatile uint16_t *tcnt_of(uint8_t k)
{
    return k == 3 ? &TCNT5 : &TCNT3;
}
/* Serve the Timer3 steppers whose pending compare a write of TIFR3 cleared (`lost`: the
 * flags up before it and down after). The hardware clears only the flags written with a
 * 1, but simavr 1.6 (avr_timer_write_pending) clears every flag of the timer: the edge
 * then came a whole timer period (4.1 ms) late. A lost wrap pass is counted here; a lost
 * edge is armed again just ahead of now (late, counted). */
static void __attribute__((noinline)) relost(uint8_t lost)
{
    for (uint8_t j = 0; j < 3; j++) {
        if (!(lost & (uint8_t)(_BV(OCF3A) << j)))
            continue;
        struct step_axis *a = &axes[j];
        if (a->wraps) {
            a->wraps--;
        } else {
            *ocr_of(j) = (uint16_t)(TCNT3 + ARM_MARGIN);
            step_engine_late++;
        }
    }
}

/* A stopped stepper's compare flag cleared (a match while it was off), before its new
 * compare is written (interrupts off). A flag another stepper's compare raises between
 * the read of TIFR3 and its write is not among the pending ones read, and simavr 1.6's
 * write clears it too: module 1's edge a whole period late when a stepper's start
 * came within those 3 cycles of its match (ramps without blocks between engine
 * segments). So an enabled compare whose count lies between the timer's count before
 * the read (less the 4 cycles simavr may raise a flag late) and after the write is
 * counted as lost as well, unless it was read as pending or is up after the write (read
 * once a flag that late has risen). */
static void __attribute__((noinline)) flags3_clear(uint8_t f, uint8_t s)
{
    /* with `s` (the caller's SREG) allowing it, another stepper's pending match is
     * served first (its interrupt clears its flag): it would go out only after the
     * arming, and its flag is one the write would lose. Once: in simavr a flag that rose
     * before its interrupt was enabled stays up unserved. */
    if ((s & _BV(SREG_I)) && (TIFR3 & TIMSK3 & (uint8_t)~f)) {
        SREG = s;
        /* (the chip runs one instruction after the enable first, simavr 1.6 two) */
        __asm__ volatile("nop\n\tnop");
        cli();
    }
    uint16_t from = (uint16_t)(TCNT3 - 4u);
    uint8_t on = (uint8_t)(TIMSK3 & (uint8_t)~f);
    uint8_t up = (uint8_t)(TIFR3 & on); /* the others' pending */
    TIFR3 = f;
    uint16_t span = (uint16_t)(TCNT3 - from);
    __builtin_avr_delay_cycles(6); /* a flag of a match up to `span` is up by now */
    uint8_t now_up = TIFR3;
    uint8_t lost = (uint8_t)(up & ~now_up);
    for (uint8_t j = 0; j < 3; j++) {
        uint8_t b = (uint8_t)(_BV(OCF3A) << j);
        if ((on & b) && !((up | now_up) & b) && (uint16_t)(*ocr_of(j) - from) <= span)
            lost |= b;
    }
    if (lost)
        relost(lost);
}
static inline __attribute__((always_inline)) void irq_clear(uint8_t k, uint8_t s)
{
    if (k == 3)
        TIFR5 = _BV(OCF5A);
    else
        flags3_clear((uint8_t)(_BV(OCF3A) << k), s);
}
/* Its interrupt on, after the new compare was written: a match since then (its first
 * timer period gone by, so close was it) is served here, as simavr 1.6 never raises an
 * interrupt enabled after its flag rose; an edge that close is armed again just ahead
 * (late). Only a compare whose first match was `near` (within 256 cycles) can have matched:
 * a flag seen after a farther one is its old compare's (a stopped stepper's compare stays
 * where its last edge was and matches once a period; one match came between the flag's
 * clearing and the new compare's write, and was taken for the new one's: the first edge
 * went out at once, up to a period early, the first layer's extruder at segment 3450),
 * and is only cleared. (Moving the old compare away first costs a compare write, and in
 * simavr 1.6 a write of any of the timer's compares drops another's match due in the same
 * cycles: a module's edge a period late.) */
static inline __attribute__((always_inline)) void irq_on(uint8_t k, struct step_axis *a,
                                                          uint8_t near)
{
    uint8_t matched;
    if (k == 3) {
        TIMSK5 |= _BV(OCIE5A);
        matched = TIFR5 & _BV(OCF5A);
    } else {
        uint8_t f = (uint8_t)(_BV(OCF3A) << k);
        TIMSK3 |= f; /* OCIE3A..C are bits 1..3 like OCF3A..C */
        matched = TIFR3 & f;
    }
    if (!matched)
        return;
    irq_clear(k, 0);
    if (!near)
        return;
    if (a->wraps)
        a->wraps--;
    else
        *ocr_of(k) = (uint16_t)(*tcnt_of(k) + ARM_MARGIN);
}
static inline __attribute__((always_inline)) void irq_off(uint8_t k)
{
    if (k == 3)
        TIMSK5 &= (uint8_t)~_BV(OCIE5A);
    else
        TIMSK3 &= (uint8_t)~(_BV(OCIE3A) << k);
}
_Static_assert(OCIE3A == OCF3A && OCIE3B == OCIE3A + 1 && OCIE3C == OCIE3A + 2, "Timer3's bits");

/* Arm stepper k's compare for its edge at t, `ahead` cycles (24 bits) from now:
 * whole timer periods first, then the compare. */
static inline __attribute__((always_inline)) void arm(uint8_t k, struct step_axis *a,
                                                       uint32_t ahead)
{
    uint16_t ocr = OCR_OF(a->t);
    if (ahead >= 0x10000UL) {
        /* the matches before the right one, counted from now, not from the edge `ahead`
         * is measured from: C's own time (under 2^15 cycles) may have taken the first
         * one past (an interval just over 2^16 cycles then came a period late) */
        /* The first match, `low` cycles from the read, must not come before the write:
         * one due within C_ARM_MARGIN cycles (or 3 just past) is let pass first (a wait
         * of at most that, about one slow arming in a thousand), then the compare is
         * written at once. (Before, a first match a few cycles ahead passed during the
         * computation and the edge came a period late, on the chip too.) */
        uint16_t low;
        while ((uint16_t)((low = (uint16_t)(ocr - *tcnt_of(k))) + 3u) < C_ARM_MARGIN + 3u)
            ;
        *ocr_of(k) = ocr;
        a->wraps = (uint8_t)((ahead - ISR_LEAD - low + 0x8000UL) >> 16);
        return;
    }
    a->wraps = 0;
    uint16_t now = *tcnt_of(k);
    if (ahead < 0x8000UL && (int16_t)(ocr - now) < ARM_MARGIN) {
        ocr = (uint16_t)(now + C_ARM_MARGIN); /* late */
        step_engine_late++;
    }
    *ocr_of(k) = ocr;
}

static inline __attribute__((always_inline)) void load(uint8_t k, struct step_axis *a,
                                                        uint32_t interval, int32_t add,
                                                        uint16_t count)
{
    a->interval = interval & 0x7FFFFFFFUL; /* (a block's mark off) */
    a->add = add;
    if (add)
        GPIOR0 |= bit_of_k[k];
    else
        GPIOR0 &= (uint8_t)~bit_of_k[k];
    a->count = count;
}

/* Take the next chunk of stepper k, at its time (the running chunk's last edge is a->t);
 * returns 0 when there is none. */
static inline __attribute__((always_inline)) uint8_t take(uint8_t k, struct step_axis *a)
{
    if (a->nblk) {
        /* the block's next chunk: its first edge where the recurrence left off */
        const struct sched_chunk *c = a->blk;
        a->t += a->interval;
        load(k, a, c->interval, c->add, c->count);
        a->blk = c + 1;
        a->nblk--;
        return 1;
    }
    if (a->next_ready) {
        a->t = a->next.t;
        load(k, a, a->next.interval, a->next.add, a->next.count);
        a->nblk = a->next.nblk;
        a->blk = a->next.blk;
        if ((uint8_t)!!(cur_dir & bit_of_k[k]) != a->next.neg)
            set_dir(k, a->next.neg);
        a->next_ready = 0;
        uint8_t flags = a->next2_ready;
        if (flags) { /* (as the assembly does: a steady chunk) */
            a->next = a->next2;
            GPIOR0 &= (uint8_t)~(bit_of_k[k] << 4);
            a->next_ready = flags;
            a->next2_ready = 0;
        }
        return 1;
    }
    uint8_t tail = a->tail;
    if (tail == a->head)
        return 0;
    const struct step_chunk *c = &a->ring[tail & (CHUNK_SLOTS - 1)];
    a->t = c->t;
    load(k, a, c->interval, c->add, c->count);
    a->nblk = c->nblk;
    a->blk = c->blk;
    if ((uint8_t)!!(cur_dir & bit_of_k[k]) != c->neg)
        set_dir(k, c->neg);
    a->tail = (uint8_t)(tail + 1);
    return 1;
}

/* the running chunk is the assembly's or C's (step_chunk_slow) */
static inline __attribute__((always_inline)) uint8_t chunk_is_slow(uint8_t k,
                                                                 const struct step_axis *a)
{
    return step_chunk_slow(a->interval, has_add(k) ? a->add : 0, a->count);
}
/* (interrupts off: step_fast is shared) */
static inline __attribute__((always_inline)) void set_slow_as(uint8_t k, struct step_axis *a,
                                                              uint8_t chunk_slow)
{
    a->slow = a->wraps || chunk_slow;
    /* (a slow chunk's edge too: its interrupt finds the pin high, as the assembly's) */
    if (a->running && !a->wraps)
        step_fast |= (uint8_t)(bit_of_k[k] << 1);
    else
        step_fast &= (uint8_t)~(bit_of_k[k] << 1);
}
static inline __attribute__((always_inline)) void set_slow(uint8_t k, struct step_axis *a)
{
    set_slow_as(k, a, chunk_is_slow(k, a));
}

/* Stepper k in C, the assembly's rare cases: a whole timer period let pass (`mode`
 * WRAP); an edge of a slow chunk (intervals of 2^15 cycles or more, under 489 steps/s:
 * EDGE, its pin raised by the assembly) and a chunk's end with no chunk waiting for the
 * assembly (END, its pin high and its count down). About 250 cycles with the compiler's
 * entry and exit; the work runs with interrupts on (the other steppers' edges keep their
 * time) until the shared bytes (cur_dir, step_fast, the pins, the compare) are touched,
 * and returns with them off. Its own compare cannot come again meanwhile: it matched
 * just now and is not rearmed before the end. */
enum { WRAP, EDGE, END };
static inline __attribute__((always_inline)) void lower_pin(uint8_t k)
{
    switch (k) {
    case 0: X_STEP_PORT &= (uint8_t)~_BV(X_STEP_BIT); break;
    case 1: Y_STEP_PORT &= (uint8_t)~_BV(Y_STEP_BIT); break;
    case 2: Z_STEP_PORT &= (uint8_t)~_BV(Z_STEP_BIT); break;
    default: E_STEP_PORT &= (uint8_t)~_BV(E_STEP_BIT); break;
    }
}
static inline __attribute__((always_inline)) void step_work(uint8_t k, uint8_t mode)
{
    struct step_axis *a = &axes[k];
    if (mode == WRAP) {
        if (!--a->wraps) {
            uint8_t slow = chunk_is_slow(k, a);
            cli();
            set_slow_as(k, a, slow);
        }
        cli();
        return;
    }
    uint32_t was = a->t;
    if (mode == EDGE && --a->count) {
        a->t = was + a->interval;
        if (has_add(k))
            a->interval += (uint32_t)a->add;
    } else {
        /* the chunk taken, or the stepper stopped, at once: a chunk pushed meanwhile
         * (step_engine_push, from the tick) must find the stepper as it is */
        cli();
        if (!take(k, a)) {
            a->running = 0;
            irq_off(k);
            set_slow_as(k, a, 0);
            goto low;
        }
        sei();
    }
    {
        uint8_t slow = chunk_is_slow(k, a);
        uint32_t ahead = cycles_of(a->t - was);
        if (ahead & 0x800000UL)
            ahead = 0; /* a chunk whose first edge has passed: at once (late), not a
                        * 2^24-cycle wait */
        cli();
        arm(k, a, ahead);
        set_slow_as(k, a, slow);
    }
low:
    lower_pin(k);
}
#define STEP_WORK(name, k)                                                                 \
    static void __attribute__((noinline)) name(uint8_t mode) { step_work(k, mode); }
STEP_WORK(work_x, 0)
STEP_WORK(work_y, 1)
STEP_WORK(work_z, 2)
STEP_WORK(work_e, 3)
static void work_of(uint8_t k, uint8_t mode)
{
    switch (k) {
    case 0: work_x(mode); break;
    case 1: work_y(mode); break;
    case 2: work_z(mode); break;
    default: work_e(mode); break;
    }
}

/* One stepper's C at a time: a stepper whose C comes while another's runs leaves its
 * work to that one (its mode + 1 in step_c_pending; its pin is high already, its next
 * compare not yet armed, so it cannot come again) and returns at once, so the stack
 * holds one C path however many steppers need one (tools/stack_usage.py). The entry in
 * assembly decides with interrupts off (a few cycles); the C path it opens runs with
 * them on from its first instruction, but with the tick's interrupt masked until it
 * ends: the tick's computation (interrupts on, up to a few hundred us) on top of an open
 * C path held every stepper whose work waited there, its compare not armed yet (a
 * module's first edge of a segment 290 us late, a ramp's chunk taken from the ring as
 * the tick came). The tick then starts at most a C path late (the harness, like the
 * chip, runs an interrupt whose flag rose while it was masked once it is enabled). */
uint8_t step_c_open;
uint8_t step_c_pending[4];
static inline __attribute__((always_inline)) void step_drain(uint8_t k, uint8_t mode)
{
    work_of(k, mode);
    for (;;) { /* (interrupts off here) */
        uint8_t j = 0;
        while (j < 4 && !step_c_pending[j])
            j++;
        if (j == 4)
            break;
        uint8_t m = (uint8_t)(step_c_pending[j] - 1);
        step_c_pending[j] = 0;
        sei();
        work_of(j, m);
    }
    step_c_open = 0;
    TIMSK1 |= _BV(OCIE1A); /* (the tick, masked while the C path was open: below) */
}

/* The rare cases, entered from the assembly as if from the vector. */
#define STEP_C(name, kk, md)                                                               \
    void name##_c(void) __attribute__((interrupt, used));                                  \
    void name##_c(void) { step_drain(kk, md); }                                           \
    void name(void) __attribute__((naked, used));                                          \
    void name(void)                                                                        \
    {                                                                                      \
        __asm__ volatile("push r24\n\t"                                                    \
                         "in r24, __SREG__\n\t"                                            \
                         "push r24\n\t"                                                    \
                         "lds r24, step_c_open\n\t"                                        \
                         "tst r24\n\t"                                                     \
                         "breq 1f\n\t"                                                     \
                         "ldi r24, %[m]\n\t"                                               \
                         "sts step_c_pending+%[k], r24\n\t"                                \
                         "pop r24\n\t"                                                     \
                         "out __SREG__, r24\n\t"                                           \
                         "pop r24\n\t"                                                     \
                         "reti\n"                                                          \
                         "1:\n\t"                                                          \
                         "ldi r24, 1\n\t"                                                  \
                         "sts step_c_open, r24\n\t"                                        \
                         "lds r24, %[timsk]\n\t"                                           \
                         "andi r24, %[noa]\n\t"                                            \
                         "sts %[timsk], r24\n\t"                                           \
                         "pop r24\n\t"                                                     \
                         "out __SREG__, r24\n\t"                                           \
                         "pop r24\n\t"                                                     \
                         "jmp " #name "_c\n\t"                                            \
                         :                                                                 \
                         : [m] "M"((md) + 1), [k] "M"(kk), [timsk] "n"(_SFR_MEM_ADDR(TIMSK1)), \
                           [noa] "M"(0xFF & ~_BV(OCIE1A)));                                \
    }
STEP_C(__vector_wrap_x, 0, WRAP)
STEP_C(__vector_wrap_y, 1, WRAP)
STEP_C(__vector_wrap_z, 2, WRAP)
STEP_C(__vector_wrap_e, 3, WRAP)
STEP_C(__vector_step_x, 0, EDGE)
STEP_C(__vector_step_y, 1, EDGE)
STEP_C(__vector_step_z, 2, EDGE)
STEP_C(__vector_step_e, 3, EDGE)
STEP_C(__vector_end_x, 0, END)
STEP_C(__vector_end_y, 1, END)
STEP_C(__vector_end_z, 2, END)
STEP_C(__vector_end_e, 3, END)
_Static_assert(offsetof(struct step_axis, wraps) + 1 == offsetof(struct step_axis, slow),
               "the assembly reads wraps before slow");

/* The common case in assembly (about 90 cycles with the interrupt's entry and exit; the
 * compiler's C saves 20 registers): pin high, count down, T += I (32 bits), or at the
 * chunk's end the waiting chunk (its time, interval, count and direction), the compare at
 * T rounded to a cycle less ISR_LEAD, or just ahead of now if that has passed already,
 * pin low (>= 2 us later). PIN_ON / PIN_OFF raise and lower the step pin, DIR_POS /
 * DIR_NEG set the direction pin (r25 free in each). */

/* T += I in 32 bits (an edge's ideal time advanced by its interval), T's bit 7 kept in
 * SREG's T flag, T's bytes 1 and 2 left in r26:r27 for the compare's value */
#define T_PLUS_I                                                                           \
    "lds r24, %[t]\n\t" \
    "lds r25, %[i]\n\t" \
    "add r24, r25\n\t" \
    "sts %[t], r24\n\t" \
    "bst r24, 7\n\t" \
    "lds r26, %[t]+1\n\t" \
    "lds r25, %[i]+1\n\t" \
    "adc r26, r25\n\t" \
    "sts %[t]+1, r26\n\t" \
    "lds r27, %[t]+2\n\t" \
    "lds r25, %[i]+2\n\t" \
    "adc r27, r25\n\t" \
    "sts %[t]+2, r27\n\t" \
    "lds r24, %[t]+3\n\t" \
    "lds r25, %[i]+3\n\t" \
    "adc r24, r25\n\t" \
    "sts %[t]+3, r24\n\t"

/* Edges due together (axes in step, or a mix's coincidences): the interrupt that fires
 * reads the other steppers' compare flags right after raising its own pin, and again
 * after arming its next compare (the ones that matched while it ran), and raises the pin
 * of each one whose flag is up and whose armed compare is an edge (step_fast); that
 * stepper's interrupt, pending, then finds its pin high already (the raise is
 * idempotent), does its bookkeeping and lowers it. An edge due with another or during
 * another's interrupt is then about 1 us late instead of up to one interrupt (about
 * 6 us) per stepper served before it; 6 cycles a check when none is pending. The check
 * at the end leaves out E (its flag is Timer5's: 2 cycles an edge less, and with them
 * 3 x 33K + E 3.3K keeps the tick inside its 400 us). r24: the pending steppers (bits as
 * step_fast), r25 scratch; `others`: the other steppers' bits. */
#define TIFR3_IO "0x18" /* iom2560.h: TIFR3, TIFR5 (OCF3A..C bits 1..3, OCF5A bit 1) */
#define TIFR5_IO "0x1A"
#define PENDING_T3 "in r24, " TIFR3_IO "\n\t"
#define PENDING_T3_T5 PENDING_T3 "sbic " TIFR5_IO ", 1\n\tori r24, 0x10\n\t"
#define RAISE_PENDING(read, others, raises)                                                \
    read "andi r24, " others "\n\t"                                                        \
    "breq 20f\n\t" /* (the common case: none pending, 6 cycles) */                        \
    "lds r25, step_fast\n\t"                                                               \
    "and r24, r25\n\t"                                                                     \
    "breq 20f\n\t" raises "20:\n\t"
#define IF_X "sbrc r24, 1\n\tsbi %[pf], %[xb]\n\t"
#define IF_Y "sbrc r24, 2\n\tsbi %[pf], %[yb]\n\t"
#define IF_Z "sbrs r24, 3\n\trjmp 21f\n\tlds r25, %[pl]\n\tori r25, %[zb]\n\tsts %[pl], r25\n21:\n\t"
#define IF_E "sbrc r24, 4\n\tsbi %[pa], %[eb]\n\t"

/* One stepper's compare interrupt (`a` its state, its timer's registers, its pins' code:
 * dir_pos and dir_neg may use r24 only, r25 holds next's flags through them). */
#define STEP_ASM(a, ocr, tcnt, timsk, mask_bit, pin_on, pin_off, dir_pos, dir_neg, dbit, slow_fn, end_fn, partners, \
                 late_partners, kidx, wrap_fn)                                            \
    __asm__ volatile(                                                                      \
        "push r24\n\t"                                                                     \
        "in r24, __SREG__\n\t"                                                             \
        "push r24\n\t"                                                                     \
        "lds r24, %[slow]\n\t"                                                             \
        "tst r24\n\t"                                                                      \
        "breq 1f\n\t"                                                                      \
        /* C's: a period to let pass, or a slow chunk's edge (its pin raised here, at  \
         * its time) */                                                                   \
        "lds r24, %[slow]-1\n\t"                                                           \
        "tst r24\n\t"                                                                      \
        "brne 51f\n\t"                                                                     \
        "push r25\n\t" pin_on                                                              \
        "pop r25\n\t"                                                                      \
        "pop r24\n\t"                                                                      \
        "out __SREG__, r24\n\t"                                                            \
        "pop r24\n\t"                                                                      \
        "jmp " slow_fn "\n"                                                                \
        "51:\n\t"                                                                          \
        "pop r24\n\t"                                                                      \
        "out __SREG__, r24\n\t"                                                            \
        "pop r24\n\t"                                                                      \
        "jmp " wrap_fn "\n"                                                                \
        "1:\n\t"                                                                           \
        "push r25\n\t" pin_on                                                              \
        "push r26\n\t"                                                                     \
        "push r27\n\t" partners \
        "lds r24, %[cnt]\n\t"                                                              \
        "lds r25, %[cnt]+1\n\t"                                                            \
        "sbiw r24, 1\n\t"                                                                  \
        "sts %[cnt]+1, r25\n\t"                                                            \
        "sts %[cnt], r24\n\t"                                                              \
        "breq 9f\n\t"                                                                      \
        "rjmp 2f\n"                                                                         \
        "9:\n\t"                                                                           \
        /* the chunk's last edge: the waiting chunk; none and none in the ring: the    \
         * stepper stops; else C takes the ring's */                                       \
        "lds r24, %[run]+6\n\t" /* a block's next chunk */                                 \
        "tst r24\n\t"                                                                      \
        "breq 44f\n\t"                                                                     \
        "rjmp 40f\n"                                                                        \
        "44:\n\t"                                                                          \
        "lds r24, %[rdy]\n\t"                                                              \
        "tst r24\n\t"                                                                      \
        "brne 6f\n\t"                                                                      \
        "lds r24, %[head]\n\t"                                                             \
        "lds r25, %[tail]\n\t"                                                             \
        "cp r24, r25\n\t"                                                                  \
        "brne 11f\n\t"                                                                     \
        "ldi r24, 0\n\t"                                                                   \
        "sts %[run], r24\n\t"                                                              \
        "lds r24, step_fast\n\t"                                                           \
        "andi r24, lo8(~(%[bit] << 1))\n\t"                                                \
        "sts step_fast, r24\n\t"                                                          \
        "lds r24, %[msk]\n\t"                                                              \
        "andi r24, lo8(~%[mbit])\n\t"                                                      \
        "sts %[msk], r24\n\t"                                                              \
        "rjmp 10f\n"                                                                        \
        "11:\n\t"                                                                          \
        "pop r27\n\t"                                                                      \
        "pop r26\n\t"                                                                      \
        "pop r25\n\t"                                                                      \
        "pop r24\n\t"                                                                      \
        "out __SREG__, r24\n\t"                                                            \
        "pop r24\n\t"                                                                      \
        "jmp " end_fn "\n"                                                                 \
        "6:\n\t" /* a waiting chunk whose first edge is about 32,000 cycles or more    \
                    * after this edge (a slow stretch across a segment's boundary) is     \
                    * C's: the lateness test below compares 16-bit times and would take   \
                    * an edge that far ahead for one past (it and the next ones then went \
                    * out at once, in the segment before theirs). Compared on T's bits    \
                    * 16..31 (cycles / 256): 16 cycles. */                                \
        "lds r24, %[nt]+2\n\t"                                                             \
        "lds r25, %[t]+2\n\t"                                                              \
        "sub r24, r25\n\t"                                                                 \
        "lds r25, %[nt]+3\n\t"                                                             \
        "lds r26, %[t]+3\n\t"                                                              \
        "sbc r25, r26\n\t"                                                                 \
        "tst r25\n\t" /* (sbc's Z holds the whole difference's) */                        \
        "brne 11b\n\t"                                                                     \
        "cpi r24, " NEXT_FAR "\n\t"                                                       \
        "brsh 11b\n\t"                                                                     \
        "lds r25, %[rdy]\n\t" /* r25: its flags (NEXT_SAME_DIR), for the direction */   \
        "clr r24\n\t"                                                                      \
        "sts %[rdy], r24\n\t"                                                              \
        /* a steady chunk (add 0, no further chunks: nblk is 0 here); a ramp's first      \
         * out of line */                                                                 \
        "cbi " GPIOR0_IO ", " kidx "\n\t"                                                 \
        "sbic " GPIOR0_IO ", 4+" kidx "\n\t"                                              \
        "rjmp 46f\n"                                                                       \
        "45:\n\t"                                                                          \
        "lds r24, %[ncnt]\n\t"                                                             \
        "sts %[cnt], r24\n\t"                                                              \
        "lds r24, %[ncnt]+1\n\t"                                                           \
        "sts %[cnt]+1, r24\n\t"                                                            \
        "lds r24, %[ni]\n\t"                                                               \
        "sts %[i], r24\n\t"                                                                \
        "lds r24, %[ni]+1\n\t"                                                             \
        "sts %[i]+1, r24\n\t"                                                              \
        "lds r24, %[ni]+2\n\t"                                                             \
        "sts %[i]+2, r24\n\t"                                                              \
        "lds r24, %[ni]+3\n\t"                                                             \
        "sts %[i]+3, r24\n\t"                                                              \
        "lds r24, %[nt]+3\n\t"                                                             \
        "sts %[t]+3, r24\n\t"                                                              \
        "lds r27, %[nt]+2\n\t"                                                             \
        "sts %[t]+2, r27\n\t"                                                              \
        "lds r26, %[nt]+1\n\t"                                                             \
        "sts %[t]+1, r26\n\t"                                                              \
        "lds r24, %[nt]\n\t"                                                               \
        "sts %[t], r24\n\t"                                                                \
        "bst r24, 7\n\t"                                                                   \
        /* the direction: the pin, and cur_dir's bit (step_tick.h), unless the push found \
         * it the running chunk's (NEXT_SAME_DIR: 3 cycles, not 13-16; never set with     \
         * NEXT2: a take with next2 waiting goes this way and moves it up at 55) */        \
        "sbrc r25, 2\n\t"                                                                  \
        "rjmp 5f\n\t"                                                                      \
        "lds r24, %[nneg]\n\t"                                                             \
        "tst r24\n\t"                                                                      \
        "brne 7f\n\t" dir_pos                                                              \
        "lds r24, cur_dir\n\t"                                                             \
        "andi r24, lo8(~%[bit])\n\t"                                                       \
        "rjmp 8f\n"                                                                        \
        "7:\n\t" dir_neg                                                                   \
        "lds r24, cur_dir\n\t"                                                             \
        "ori r24, %[bit]\n"                                                                \
        "8:\n\t"                                                                           \
        "sts cur_dir, r24\n\t"                                                             \
        "sbrs r25, 3\n\t" /* NEXT2 in r25, next's flags (the direction code keeps r25) */  \
        "rjmp 5f\n\t"                                                                      \
        "rjmp 55f\n"                                                                        \
        "2:\n\t"                                                                           \
        T_PLUS_I                                                                           \
        /* a ramp's chunk: I += add, out of line (2 cycles an edge without) */            \
        "sbic " GPIOR0_IO ", " kidx "\n\t"                                                \
        "rjmp 30f\n"                                                                       \
        "5:\n\t"                                                                           \
        "subi r26, lo8(%[lead])\n\t"                                                       \
        "sbci r27, hi8(%[lead])\n\t"                                                       \
        "brtc 3f\n\t"                                                                      \
        "adiw r26, 1\n"                                                                    \
        "3:\n\t"                                                                           \
        "lds r24, %[tc]\n\t"                                                               \
        "lds r25, %[tc]+1\n\t"                                                             \
        "adiw r24, %[margin]\n\t"                                                          \
        "cp r24, r26\n\t"                                                                  \
        "cpc r25, r27\n\t"                                                                 \
        "brmi 4f\n\t"                                                                      \
        "movw r26, r24\n"                                                                  \
        "4:\n\t"                                                                           \
        "sts %[oc]+1, r27\n\t"                                                             \
        "sts %[oc], r26\n\t" late_partners                                                   \
        "10:\n\t"                                                                          \
        "pop r27\n\t"                                                                      \
        "pop r26\n\t" pin_off                                                              \
        "pop r25\n\t"                                                                      \
        "pop r24\n\t"                                                                      \
        "out __SREG__, r24\n\t"                                                            \
        "pop r24\n\t"                                                                      \
        "reti\n"                                                                           \
        /* next2 waiting (its direction code done): next2 (at %[nt]+18 its flags, then its  \
         * chunk: a steady one) moves up into next: its time, interval, count and        \
         * direction, add and nblk zeroed (about 70 cycles) */                           \
        "55:\n\t"                                                                          \
        "lds r24, %[nt]+19\n\t"                                                            \
        "sts %[nt]+0, r24\n\t"                                                             \
        "lds r24, %[nt]+20\n\t"                                                            \
        "sts %[nt]+1, r24\n\t"                                                             \
        "lds r24, %[nt]+21\n\t"                                                            \
        "sts %[nt]+2, r24\n\t"                                                             \
        "lds r24, %[nt]+22\n\t"                                                            \
        "sts %[nt]+3, r24\n\t"                                                             \
        "lds r24, %[nt]+23\n\t"                                                            \
        "sts %[nt]+4, r24\n\t"                                                             \
        "lds r24, %[nt]+24\n\t"                                                            \
        "sts %[nt]+5, r24\n\t"                                                             \
        "lds r24, %[nt]+25\n\t"                                                            \
        "sts %[nt]+6, r24\n\t"                                                             \
        "lds r24, %[nt]+26\n\t"                                                            \
        "sts %[nt]+7, r24\n\t"                                                             \
        "lds r24, %[nt]+27\n\t"                                                            \
        "sts %[nt]+8, r24\n\t"                                                             \
        "lds r24, %[nt]+28\n\t"                                                            \
        "sts %[nt]+9, r24\n\t"                                                             \
        "lds r24, %[nt]+29\n\t"                                                            \
        "sts %[nt]+10, r24\n\t"                                                            \
        "lds r24, %[nt]+18\n\t"                                                            \
        "sts %[rdy], r24\n\t"                                                              \
        "clr r24\n\t"                                                                      \
        "sts %[nt]+18, r24\n\t"                                                            \
        "sts %[nt]+11, r24\n\t"                                                            \
        "sts %[nt]+12, r24\n\t"                                                            \
        "sts %[nt]+13, r24\n\t"                                                            \
        "sts %[nt]+14, r24\n\t"                                                            \
        "sts %[nt]+15, r24\n\t"                                                            \
        "rjmp 5b\n"                                                                        \
        "30:\n\t" /* I += add (the flags change; T's bit 7 lives in SREG's T); I's top     \
                     * byte stays 0: an assembly chunk's intervals are all under 2^23     \
                     * (step_chunk_slow), so the sum's is 0 whatever add's */             \
        "lds r24, %[i]\n\t"                                                                \
        "lds r25, %[run]+2\n\t"                                                            \
        "add r24, r25\n\t"                                                                 \
        "sts %[i], r24\n\t"                                                                \
        "lds r24, %[i]+1\n\t"                                                              \
        "lds r25, %[run]+3\n\t"                                                            \
        "adc r24, r25\n\t"                                                                 \
        "sts %[i]+1, r24\n\t"                                                              \
        "lds r24, %[i]+2\n\t"                                                              \
        "lds r25, %[run]+4\n\t"                                                            \
        "adc r24, r25\n\t"                                                                 \
        "sts %[i]+2, r24\n\t"                                                              \
        "rjmp 5b\n"                                                                        \
        "40:\n\t" /* a block's next chunk (r24: the chunks left): T += I, then its count, \
                     * interval and add; one marked slow is C's */                        \
        "push r30\n\t"                                                                     \
        "push r31\n\t"                                                                     \
        "lds r30, %[run]+7\n\t"                                                            \
        "lds r31, %[run]+8\n\t"                                                            \
        "ldd r25, Z+5\n\t"                                                                 \
        "sbrc r25, 7\n\t"                                                                  \
        "rjmp 41f\n\t"                                                                     \
        "dec r24\n\t"                                                                      \
        "sts %[run]+6, r24\n\t"                                                            \
        T_PLUS_I                                                                           \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[cnt], r24\n\t"                                                              \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[cnt]+1, r24\n\t"                                                            \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[i], r24\n\t"                                                                \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[i]+1, r24\n\t"                                                              \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[i]+2, r24\n\t"                                                              \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[i]+3, r24\n\t"                                                              \
        "clr r25\n\t"                                                                      \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[run]+2, r24\n\t"                                                            \
        "or r25, r24\n\t"                                                                  \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[run]+3, r24\n\t"                                                            \
        "or r25, r24\n\t"                                                                  \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[run]+4, r24\n\t"                                                            \
        "or r25, r24\n\t"                                                                  \
        "ld r24, Z+\n\t"                                                                   \
        "sts %[run]+5, r24\n\t"                                                            \
        "or r25, r24\n\t"                                                                  \
        "sts %[run]+7, r30\n\t"                                                            \
        "sts %[run]+8, r31\n\t"                                                            \
        "pop r31\n\t"                                                                      \
        "pop r30\n\t"                                                                      \
        "cbi " GPIOR0_IO ", " kidx "\n\t"                                                 \
        "tst r25\n\t"                                                                      \
        "breq 43f\n\t"                                                                     \
        "sbi " GPIOR0_IO ", " kidx "\n"                                                    \
        "43:\n\t"                                                                          \
        "rjmp 5b\n"                                                                        \
        "41:\n\t"                                                                          \
        "pop r31\n\t"                                                                      \
        "pop r30\n\t"                                                                      \
        "rjmp 11b\n"                                                                       \
        "46:\n\t" /* the waiting chunk's add and block (a ramp's first chunk) */          \
        "cbi " GPIOR0_IO ", 4+" kidx "\n\t"                                               \
        "clr r26\n\t" /* (r25 keeps next's flags: NEXT_SAME_DIR, NEXT2) */          \
        "lds r24, %[nneg]+1\n\t"                                                           \
        "sts %[run]+2, r24\n\t"                                                            \
        "or r26, r24\n\t"                                                                  \
        "lds r24, %[nneg]+2\n\t"                                                           \
        "sts %[run]+3, r24\n\t"                                                            \
        "or r26, r24\n\t"                                                                  \
        "lds r24, %[nneg]+3\n\t"                                                           \
        "sts %[run]+4, r24\n\t"                                                            \
        "or r26, r24\n\t"                                                                  \
        "lds r24, %[nneg]+4\n\t"                                                           \
        "sts %[run]+5, r24\n\t"                                                            \
        "or r26, r24\n\t"                                                                  \
        "breq 47f\n\t"                                                                     \
        "sbi " GPIOR0_IO ", " kidx "\n"                                                    \
        "47:\n\t"                                                                          \
        "lds r24, %[nneg]+5\n\t"                                                           \
        "sts %[run]+6, r24\n\t"                                                            \
        "lds r24, %[nneg]+6\n\t"                                                           \
        "sts %[run]+7, r24\n\t"                                                            \
        "lds r24, %[nneg]+7\n\t"                                                           \
        "sts %[run]+8, r24\n\t"                                                            \
        "rjmp 45b\n\t"                                                                     \
        :                                                                                  \
        : [slow] "i"(&(a).slow), [cnt] "i"(&(a).count), [t] "i"(&(a).t),                   \
          [i] "i"(&(a).interval), [rdy] "i"(&(a).next_ready), [nt] "i"(&(a).next.t),       \
          [ni] "i"(&(a).next.interval), [ncnt] "i"(&(a).next.count),                       \
          [nneg] "i"(&(a).next.neg), [bit] "M"(dbit), [lead] "n"(ISR_LEAD),                 \
          [head] "i"(&(a).head), [tail] "i"(&(a).tail), [run] "i"(&(a).running),           \
          [msk] "n"(_SFR_MEM_ADDR(timsk)), [mbit] "M"(mask_bit),                               \
          [margin] "n"(ARM_MARGIN), [tc] "n"(_SFR_MEM_ADDR(tcnt)),                         \
          [oc] "n"(_SFR_MEM_ADDR(ocr)), [pf] "I"(_SFR_IO_ADDR(PORTF)),                     \
          [pa] "I"(_SFR_IO_ADDR(PORTA)), [pl] "n"(_SFR_MEM_ADDR(PORTL)),                   \
          [xb] "I"(X_STEP_BIT), [yb] "I"(Y_STEP_BIT), [zb] "M"(_BV(Z_STEP_BIT)),           \
          [eb] "I"(E_STEP_BIT), [xd] "I"(X_DIR_BIT), [yd] "I"(Y_DIR_BIT),                  \
          [zd] "M"(_BV(Z_DIR_BIT)), [ed] "I"(E_DIR_BIT))

ISR(TIMER3_COMPA_vect, ISR_NAKED)
{
    STEP_ASM(axes[0], OCR3A, TCNT3, TIMSK3, _BV(OCIE3A), "sbi %[pf], %[xb]\n\t", "cbi %[pf], %[xb]\n\t",
             "sbi %[pf], %[xd]\n\t", "cbi %[pf], %[xd]\n\t", 1, "__vector_step_x",
             "__vector_end_x", RAISE_PENDING(PENDING_T3_T5, "0x1C", IF_Y IF_Z IF_E),
             RAISE_PENDING(PENDING_T3, "0x0C", IF_Y IF_Z), "0", "__vector_wrap_x");
}
ISR(TIMER3_COMPB_vect, ISR_NAKED)
{
    STEP_ASM(axes[1], OCR3B, TCNT3, TIMSK3, _BV(OCIE3B), "sbi %[pf], %[yb]\n\t", "cbi %[pf], %[yb]\n\t",
             "sbi %[pf], %[yd]\n\t", "cbi %[pf], %[yd]\n\t", 2, "__vector_step_y",
             "__vector_end_y", RAISE_PENDING(PENDING_T3_T5, "0x1A", IF_X IF_Z IF_E),
             RAISE_PENDING(PENDING_T3, "0x0A", IF_X IF_Z), "1", "__vector_wrap_y");
}
ISR(TIMER3_COMPC_vect, ISR_NAKED)
{
    STEP_ASM(axes[2], OCR3C, TCNT3, TIMSK3, _BV(OCIE3C), "lds r25, %[pl]\n\tori r25, %[zb]\n\tsts %[pl], r25\n\t",
             "lds r25, %[pl]\n\tandi r25, lo8(~%[zb])\n\tsts %[pl], r25\n\t",
             "lds r24, %[pl]\n\tori r24, %[zd]\n\tsts %[pl], r24\n\t",
             "lds r24, %[pl]\n\tandi r24, lo8(~%[zd])\n\tsts %[pl], r24\n\t", 4,
             "__vector_step_z", "__vector_end_z", RAISE_PENDING(PENDING_T3_T5, "0x16", IF_X IF_Y IF_E),
             RAISE_PENDING(PENDING_T3, "0x06", IF_X IF_Y), "2", "__vector_wrap_z");
}
ISR(TIMER5_COMPA_vect, ISR_NAKED)
{
    STEP_ASM(axes[3], OCR5A, TCNT5, TIMSK5, _BV(OCIE5A), "sbi %[pa], %[eb]\n\t", "cbi %[pa], %[eb]\n\t",
             "sbi %[pa], %[ed]\n\t", "cbi %[pa], %[ed]\n\t", 8, "__vector_step_e",
             "__vector_end_e", RAISE_PENDING(PENDING_T3, "0x0E", IF_X IF_Y IF_Z),
             RAISE_PENDING(PENDING_T3, "0x0E", IF_X IF_Y IF_Z), "3", "__vector_wrap_e");
}
_Static_assert(!X_DIR_INVERT && !Y_DIR_INVERT && !Z_DIR_INVERT && !E_DIR_INVERT,
               "the assembly sets a direction pin high for positive steps");
/* (the assembly assumes the RAMPS step ports: X and Y on PORTF, Z on PORTL, E on PORTA) */

/* now on the steppers' clock (Q24.8), from the tick in progress: less than a
 * timer period has passed since it started */
static uint32_t now_q(uint8_t k, uint32_t tick_start)
{
    uint16_t since = (uint16_t)(*tcnt_of(k) - (uint16_t)cycles_of(tick_start));
    return tick_start + q_of(since);
}

/* A stopped stepper's first chunk (its interrupt is off: only the shared bytes and the
 * arming are masked) */
static void __attribute__((noinline)) start_axis(uint8_t k, struct step_axis *a)
{
    uint8_t s = SREG;
    cli();
    take(k, a);
    SREG = s;
    uint8_t slow = step_chunk_slow_here(a->interval, has_add(k) ? a->add : 0, a->count);
    cli();
    uint32_t now = now_q(k, step_clock_this_tick);
    uint32_t ahead = cycles_of(a->t - now);
    if (ahead & 0x800000UL)
        ahead = 0; /* past already: at once (late) */
    irq_clear(k, s);
    arm(k, a, ahead);
    /* the compare's first match from now (its timer periods to let pass aside) */
    uint16_t first = (uint16_t)(*ocr_of(k) - *tcnt_of(k));
    a->running = 1;
    set_slow_as(k, a, slow);
    irq_on(k, a, (uint16_t)(first + 0x100) < 0x200);
    SREG = s;
}

/* whether the assembly may not run chunk c (a steady one's test without the outlined
 * general case's products) */
static inline __attribute__((always_inline)) uint8_t slow_chunk(const struct step_chunk *c)
{
    return c->add ? step_chunk_slow(c->interval, c->add, c->count) : c->interval >= 0x800000UL;
}

/* A chunk waits for the assembly of stepper `bit` in next (the running chunk's last edge
 * takes it). Written with interrupts on (the interrupt reads next only once its flag is
 * set), then marked ready with them off if the stepper is still as it was. */

/* next's flags for chunk c: NEXT_ADD (an add, or a block's further chunks), and
 * NEXT_SAME_DIR when it goes the running chunk's way (cur_dir) */
static inline __attribute__((always_inline)) uint8_t next_flags(uint8_t bit,
                                                                const struct step_chunk *c)
{
    uint8_t flags = c->add || c->nblk ? NEXT_READY | NEXT_ADD : NEXT_READY;
    return !!(cur_dir & bit) == c->neg ? flags | NEXT_SAME_DIR : flags;
}

/* next marked ready with `flags` (interrupts off): bit 4 + k of GPIOR0 is its NEXT_ADD */
static inline __attribute__((always_inline)) void mark_next(struct step_axis *a, uint8_t bit,
                                                            uint8_t flags)
{
    if (flags & NEXT_ADD)
        GPIOR0 |= (uint8_t)(bit << 4);
    else
        GPIOR0 &= (uint8_t)~(bit << 4);
    a->next_ready = flags;
}

/* whether the slots may take a chunk now (else the ring does, after what it holds) */
static inline __attribute__((always_inline)) uint8_t slots_open(const struct step_axis *a)
{
    return a->running && !a->next2_ready && a->head == a->tail;
}

/* Any chunk the assembly may run into next (tried again once should the assembly take
 * next meanwhile); 0: the ring's. Only steady chunks go to next2 (step_engine_push_steadies): the
 * assembly moves next2 up with its 11 bytes, a ramp's chunk has 18. */
static uint8_t __attribute__((noinline)) offer(struct step_axis *a, uint8_t bit,
                                                const struct step_chunk *c)
{
    for (uint8_t tries = 0; tries < 2 && slots_open(a) && !a->next_ready; tries++) {
        a->next = *c;
        uint8_t flags = next_flags(bit, c);
        uint8_t s = SREG;
        cli();
        uint8_t still = slots_open(a) && !a->next_ready;
        if (still)
            mark_next(a, bit, flags);
        SREG = s;
        if (still)
            return 1;
    }
    return 0;
}

/* a steady chunk's fields in its slot (the assembly reads t, interval, count, neg) */
static inline __attribute__((always_inline)) void put_steady(struct step_chunk *slot, uint32_t t,
                                                             uint32_t interval, uint16_t count,
                                                             uint8_t neg)
{
    slot->t = t;
    slot->interval = interval;
    slot->count = count;
    slot->neg = neg;
    slot->add = 0;
    slot->nblk = 0;
}

/* One stepper's steady chunk of a segment (step_engine_push_steadies), at addresses known
 * when compiled: the slot written with interrupts on, placed with them off if the stepper
 * still runs and its next slot is as it was (the assembly may take next meanwhile: a
 * chunk written to next2 would then wait behind nothing). A stopped stepper (its slots
 * and its ring empty) takes it from next at once (start_axis): a stepper stops in every
 * segment it has no step in (the extruder's, at a tenth of the modules' rate), and
 * through the ring its start cost about twice as much. Only the tick, the caller, pushes
 * or starts a stepper: one found running may stop meanwhile, one found stopped stays so. */
static inline __attribute__((always_inline)) uint8_t steady_of(uint8_t k, uint32_t start,
                                                                const uint8_t *interval_at,
                                                                const int32_t *n)
{
    struct step_axis *a = &axes[k];
    uint32_t interval = *(const uint32_t *)(interval_at + k * STEP_STEADY_STRIDE);
    if (interval >= 0x800000UL || a->next2_ready || a->head != a->tail)
        return 0;
    int32_t d = n[k];
    uint8_t neg = d < 0;
    uint16_t count = (uint16_t)d; /* (|d| < 2^16: the segment passed the rate check) */
    if (neg)
        count = (uint16_t)-count;
    uint32_t t = start + (interval >> 1);
    uint8_t bit = bit_of_k[k];
    uint8_t s;
    if (!a->running) {
        put_steady(&a->next, t, interval, count, neg);
        GPIOR0 &= (uint8_t)~(bit << 4);
        a->next_ready = NEXT_READY;
        start_axis(k, a);
        return 1;
    }
    if (a->next_ready) {
        put_steady(&a->next2, t, interval, count, neg);
        uint8_t flags = a->next.neg == neg ? NEXT_READY | NEXT_SAME_DIR : NEXT_READY;
        s = SREG;
        cli();
        if (!a->running || !a->next_ready) {
            SREG = s;
            return 0;
        }
        /* next's take then goes through the direction code, which moves next2 up */
        a->next2_ready = flags;
        a->next_ready = (uint8_t)((a->next_ready & (uint8_t)~NEXT_SAME_DIR) | NEXT2);
    } else {
        put_steady(&a->next, t, interval, count, neg);
        uint8_t flags = !!(cur_dir & bit) == neg ? NEXT_READY | NEXT_SAME_DIR : NEXT_READY;
        s = SREG;
        cli();
        if (!a->running || a->next_ready) {
            SREG = s;
            return 0;
        }
        GPIOR0 &= (uint8_t)~(bit << 4);
        a->next_ready = flags;
    }
    SREG = s;
    return 1;
}

uint8_t step_engine_push_steadies(uint32_t start, uint8_t mask, const uint8_t *interval_at,
                                  const int32_t *n)
{
    uint8_t left = mask;
    if ((mask & 1) && steady_of(0, start, interval_at, n))
        left &= (uint8_t)~1;
    if ((mask & 2) && steady_of(1, start, interval_at, n))
        left &= (uint8_t)~2;
    if ((mask & 4) && steady_of(2, start, interval_at, n))
        left &= (uint8_t)~4;
    if ((mask & 8) && steady_of(3, start, interval_at, n))
        left &= (uint8_t)~8;
    return left;
}

/* The ring's first chunk moved up into next, which the assembly emptied as it took the
 * chunk there: the ring's chunk went to the ring only because next held one then (a
 * block's chunk, which next2 does not take, behind a short segment's), and a chunk after
 * it may not pass it. Frees the ring's slot for that chunk (three 0.65 ms segments, two
 * ramps with their blocks and a steady one: the steady one found the ring full and its
 * steps were lost). Written with interrupts on (next is not read while next_ready is 0),
 * moved with them off if the ring's chunk is still there (C takes it at the running
 * chunk's end when next is empty). */
static uint8_t __attribute__((noinline)) promote(struct step_axis *a, uint8_t bit)
{
    uint8_t tail = a->tail;
    const struct step_chunk *c = &a->ring[tail & (CHUNK_SLOTS - 1)];
    if (!a->running || a->next_ready || tail == a->head || slow_chunk(c))
        return 0; /* (next2 holds a chunk only while next does) */
    a->next = *c;
    uint8_t flags = next_flags(bit, c);
    uint8_t s = SREG;
    cli();
    uint8_t still = a->running && !a->next_ready && a->tail == tail;
    if (still) {
        mark_next(a, bit, flags);
        a->tail = (uint8_t)(tail + 1);
    }
    SREG = s;
    return still;
}

uint8_t step_engine_push(uint8_t k, const struct step_chunk *c)
{
    struct step_axis *a = &axes[k];
    if (!slow_chunk(c) && offer(a, bit_of_k[k], c))
        return 1;
    uint8_t s = SREG;
    uint8_t head = a->head;
    if ((uint8_t)(head - a->tail) >= CHUNK_SLOTS && !promote(a, bit_of_k[k]))
        return 0;
    a->ring[head & (CHUNK_SLOTS - 1)] = *c;
    cli();
    a->head = (uint8_t)(head + 1);
    /* (a stepper's C stops it in one masked piece with the ring found empty: running
     * read after the chunk is in is either still 1, and the chunk taken, or 0) */
    uint8_t running = a->running;
    SREG = s;
    if (!running)
        start_axis(k, a);
    return 1;
}

void step_engine_stop(void)
{
    uint8_t s = SREG;
    cli();
    TIMSK3 = 0;
    TIMSK5 = 0;
    step_fast = 0;
    GPIOR0 = 0;
    for (uint8_t k = 0; k < 4; k++) {
        if (step_c_pending[k]) /* its pin raised, its work left (a C path running finds none) */
            lower_pin(k);
        step_c_pending[k] = 0;
    }
    for (uint8_t k = 0; k < 4; k++) {
        axes[k].running = 0;
        axes[k].next_ready = 0;
        axes[k].next2_ready = 0;
        axes[k].tail = axes[k].head;
        axes[k].count = 0;
        axes[k].nblk = 0;
    }
    SREG = s;
}

/* The edges of a chunk and of the schedule block's chunks after it. */
static uint32_t chunk_edges(uint16_t count, uint8_t nblk, const struct sched_chunk *blk)
{
    uint32_t n = count;
    for (; nblk; nblk--, blk++)
        n += blk->count;
    return n;
}

int32_t step_engine_unissued(uint8_t k)
{
    const struct step_axis *a = &axes[k];
    int32_t n = 0;
    if (a->running) {
        /* the armed edge is in count; an EDGE left to C has its pin raised already */
        uint32_t left = chunk_edges(a->count, a->nblk, a->blk);
        if (step_c_pending[k] == EDGE + 1 && left)
            left--;
        n = (cur_dir & bit_of_k[k]) ? -(int32_t)left : (int32_t)left;
    }
    if (a->next_ready) {
        int32_t m = (int32_t)chunk_edges(a->next.count, a->next.nblk, a->next.blk);
        n += a->next.neg ? -m : m;
    }
    if (a->next2_ready) {
        int32_t m = (int32_t)chunk_edges(a->next2.count, a->next2.nblk, a->next2.blk);
        n += a->next2.neg ? -m : m;
    }
    for (uint8_t t = a->tail; t != a->head; t++) {
        const struct step_chunk *c = &a->ring[t & (CHUNK_SLOTS - 1)];
        int32_t m = (int32_t)chunk_edges(c->count, c->nblk, c->blk);
        n += c->neg ? -m : m;
    }
    return n;
}

uint8_t step_engine_idle(void)
{
    for (uint8_t k = 0; k < 4; k++) {
        const struct step_axis *a = &axes[k];
        if (a->running || a->next_ready || a->next2_ready || a->head != a->tail)
            return 0;
    }
    return 1;
}
#endif
