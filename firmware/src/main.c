/* cdpr firmware for an ATmega2560 on a RAMPS 1.4: the main loop.
 * The host decides, the MCU obeys: the interrupt executes the move queue, this
 * loop moves bytes, decodes commands, controls the heaters and reports. */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "autotune.h"
#include "board_ramps14.h"
#include "frame.h"
#include "commands.h"
#include "heater.h"
#include "link.h"
#include "machine.h"
#include "motion.h"
#include "protocol_gen.h"
#include "queue.h"
#include "reports.h"
#include "sched.h"
#include "session.h"
#include "sim_hooks.h"
#include "step_timer.h"
#include "stepper.h"
#include "uart.h"
#include "watchdog.h"

/* Clock units per main-loop turn spent executing the held frames (10 ms at most: it
 * ends sooner when they are done): a time, not a count of messages, so short segments
 * are executed as fast as they are checked and the turn's fixed work does not limit
 * the rate (the plans are prepared between the messages, the UART ring holds what
 * arrives meanwhile). */
#define EXEC_UNITS 1000
static uint16_t loop_worst_us;

/* A counter the step interrupts write, read with them masked for its own few cycles
 * only: compare B masked for longer (a window around all of HEALTH's counters would be
 * over 100 cycles) makes a step edge late by several us. */
static uint16_t read_u16(const volatile uint16_t *p)
{
    uint8_t s = SREG;
    cli();
    uint16_t v = *p;
    SREG = s;
    return v;
}

static void health_read(struct health *out)
{
    uint8_t s = SREG;
    cli();
    uint32_t late = stepper_late_tolerance;
    SREG = s;
    out->late_pulses = late;
    out->late_worst_us = (read_u16(&stepper_late_worst) + UNIT_CYCLES / 20) / (F_CPU / 1000000UL);
    out->lost_steps = read_u16(&stepper_lost_steps);
    out->tick_overruns = read_u16(&stepper_overruns);
    out->plan_stalls = read_u16(&stepper_plan_stalls);
    out->rx_overruns = uart_rx_overruns();
    out->loop_worst_us = loop_worst_us;
}

void sched_update_link_time(void)
{
    /* in the simulator the harness's wall clock (sim_hooks.h) */
    link_now = sim_link_clock(sched_clock());
}

/* A WAIT item is done at once when its heater's target is 0, else within the
 * tolerance. Decided with interrupts masked, for the WAIT executing at that moment
 * and with no target change still on its way from the interrupt, so a WAIT that
 * follows another (or a SET_HEATER) is never satisfied by the other one's state. */
static void decide_wait(void)
{
    uint8_t s = SREG, id = 0;
    uint16_t tolerance = 0;
    cli();
    uint8_t wait = stepper_waiting_for(&id, &tolerance);
    if (wait != WAIT_NONE) {
        const struct heater *h = &heaters[id];
        int16_t diff = (int16_t)(h->temp_dc - (int16_t)h->target_dc);
        if (diff < 0)
            diff = (int16_t)-diff;
        stepper_wait_ok = wait == WAIT_HEATER &&
                          (!h->target_dc || (uint16_t)diff <= tolerance);
    }
    SREG = s;
}

static void take_interrupt_reports(uint32_t now)
{
    static uint8_t thermal_reported[2];
    struct stepper_report r = {0};
    uint16_t targets[2] = {0, 0};
    /* The one-byte flags are read with interrupts on: the copy with them masked (long
     * enough to delay a step tick by several us) only when there is something to take. */
    if (stepper_report.homed || stepper_report.error) {
        cli();
        r = *(struct stepper_report *)&stepper_report;
        stepper_report.homed = 0;
        stepper_report.error = 0;
        sei();
    }
    uint8_t changed = stepper_take_heater_targets(targets);
    for (uint8_t i = 0; i < 2; i++)
        if (changed >> i & 1)
            heater_set_target(i, targets[i], now);
    if (r.homed) {
        int32_t pos[4];
        stepper_positions(pos);
        report_event(EVT_HOMED, r.homed_item, 3, pos);
    }
    if (r.error == ERR_ENDSTOP_HIT && r.axis < 3) {
        /* a limit switch: where the module is, as a physical step (0 at its homing
         * switch) once homed */
        int32_t pos[4];
        stepper_positions(pos);
        r.value = pos[r.axis] - ((stepper_homed_mask() >> r.axis & 1) ? machine.home_at[r.axis] : 0);
    }
    if (r.error)
        machine_fail(r.error, r.item, r.segment, r.axis, r.value);
    if (!(heaters[0].reached_event | heaters[0].fault | heaters[1].reached_event |
          heaters[1].fault)) {
        decide_wait();
        return;
    }
    uint32_t items, segs;
    stepper_counts(&items, &segs);
    for (uint8_t i = 0; i < 2; i++) {
        struct heater *h = &heaters[i];
        if (h->reached_event) {
            h->reached_event = 0;
            int32_t v[2] = {i, h->temp_dc};
            report_event(EVT_HEATER_REACHED, items, 2, v);
        }
        if (h->fault) {
            uint8_t code = h->fault;
            h->fault = 0;
            /* every thermal fault is reported once, faulted or not (it latches; an
             * over-temperature that persists is not repeated every period) */
            if (thermal_reported[i] != code) {
                thermal_reported[i] = code;
                machine_fail(code, items, segs, i, h->temp_dc);
            } else {
                heater_outputs_off();
            }
        }
    }
    decide_wait();
}

/* What a reset keeps (watchdog.c): the progress and the motors enabled. Its own frame:
 * the snapshot is not on the stack under the main loop's deepest calls. */
static void __attribute__((noinline)) save_progress(void)
{
    /* only after a tick or a main-loop change since the last copy (an idle turn spent a
     * fifth of itself on the copy); a tick that comes after the mark is read is seen at
     * the next turn */
    static uint16_t saved_mark;
    static uint8_t saved_once;
    uint16_t mark = stepper_change_mark();
    if (saved_once && mark == saved_mark)
        return;
    saved_mark = mark;
    saved_once = 1;
    struct stepper_progress done;
    stepper_progress(&done);
    watchdog_save(done.items_done, done.segments_done, done.enabled_mask);
}

/* A plan between two pieces of a long job: with short segments the plans last only a
 * few milliseconds, less than a turn's work on a damaged stream. */
static void prepare_one(void)
{
    motion_prepare_ahead(1);
}

int main(void)
{
    sim_boot();
    /* The layers are wired here: each names only those below it, and what it hands up
     * goes through these tables (the transport knows nothing above it, the machine
     * neither the commands nor the reports, the heater not the autotune above it). */
    static const struct frame_upper frame_up = {link_frame_received, link_frame_rejected,
                                                prepare_one};
    static const struct machine_upper machine_up = {report_error, proto_pending_items};
    static const struct autotune_upper autotune_up = {report_event, machine_fail};
    static const struct heater_override relay = {autotune_heater, autotune_relay};
    deframer_attach(&frame_up);
    machine_attach(&machine_up);
    autotune_attach(&autotune_up);
    heater_attach_override(&relay);
    reports_attach_health(health_read);
    LED_DDR |= _BV(LED_BIT);
    heater_init();
    watchdog_start();
    /* after any reset that kept the RAM (watchdog, RESET pin, soft) the motors that were
     * enabled stay enabled, as .init3 drove them: the effector hangs on them (positions
     * are unknown: the host re-homes) */
    stepper_init(watchdog_prev_enabled());
    uart_init();
    static const struct link_upper upper = {proto_accept, proto_urgent, proto_flow,
                                            proto_frame_seen};
    link_attach(&upper);
    link_reset_session();
    sei();
    uint32_t last = sched_clock();
    uint8_t turns = 0, canary_reported = 0;
    for (;;) {
        uint32_t now = sched_clock();
        watchdog_kick(now);
        sched_update_link_time();
        uint16_t loop_us = (uint16_t)((now - last) * (1000000UL / CLOCK_HZ));
        if (loop_us > loop_worst_us)
            sim_loop_max_us(loop_worst_us = loop_us);
        last = now;
        /* bounded work per turn: the held frames for a while, the plans, the received
         * bytes, one frame checked, then everything else */
        proto_execute(EXEC_UNITS);
        motion_prepare_ahead(PLAN_SLOTS);
        deframer_receive(); /* all of it: the ring is small */
        deframer_run(); /* checks and acknowledges at most one frame */
        motion_prepare_ahead(PLAN_SLOTS);
        take_interrupt_reports(now);
        heater_poll(now);
        autotune_poll(now);
        motion_prepare_ahead(PLAN_SLOTS); /* 0.5 ms segments: 8 plans last 4 ms */
#if STEP_ENGINE
        stepper_start_for = session_start_for();
#else
        stepper_start_ok = session_may_start();
#endif
        session_poll(link_now);
        link_poll(link_now);
        motion_prepare_ahead(PLAN_SLOTS);
        save_progress();
        if (!watchdog_canary_ok() && !canary_reported) {
            canary_reported = 1; /* once: the state below it may be damaged */
            uint32_t items, segs;
            stepper_counts(&items, &segs);
            machine_fail(ERR_STACK_OVERFLOW, items, segs, 0xFF, 0);
        }
        SIM_STATS(stepper_isr_max_cycles, stepper_lost_steps, stepper_plan_stalls,
                  stepper_overruns, stepper_late_pulses, stepper_latency_max, machine.last_error);
        if (SIM_HOOKS && !++turns) /* the stack's high-water mark, now and then (~1 KB scan) */
            sim_stack_free(watchdog_stack_free());
    }
}
