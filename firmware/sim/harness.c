/* cdpr-sim: the firmware ELF in simavr behind a pseudo-terminal.
 *
 *   cdpr-sim FIRMWARE.elf [--speedup X] [--record FILE] [--stats FILE]
 *            [--time-limit SIM_SECONDS] [--exit-on-hangup]
 *            [--heater-fail-after SIM_SECONDS] [--boot-physical STEPS]
 *            [--thermistor-open-after SIM_SECONDS] [--thermistor-short-after SIM_SECONDS]
 *            [--hotend-start-c C]
 *            [--travel-steps STEPS] [--bootloader HEX] [--smash-canary-after S]
 *            [--hang-main-after S]
 *
 * With --bootloader the chip boots as a Mega 2560 does: the hex (Debian's
 * arduino-core-avr stk500boot_v2_mega2560.hex) at the boot section 0x3E000 and the
 * fuses a Mega ships with (low 0xFF, high 0xD8: BOOTRST, 4 K words; extended 0xFD), so
 * every reset runs the bootloader before the application. Signals ask for resets the
 * pty cannot carry: SIGUSR1 pulls the RESET pin (the DTR auto-reset of opening the port;
 * SRAM is kept, MCUSR gets EXTRF), SIGUSR2 resets it as its watchdog does after a hang
 * (MCUSR gets WDRF; simavr 1.6's own watchdog did not reset this chip when Timer1 was
 * stopped, so the harness applies the reset). The stats count the resets and, per enable pin, whether it
 * went high (driver off) between a reset and the host's first byte after it.
 *
 * The first line on stdout is the pty path. Single-threaded: a cycle timer polls
 * the pty every POLL_US of simulated time, feeds received bytes to UART0 only
 * while the UART signals XON, buffers the UART's output without limit, paces
 * simulated time to wall time (times the speed-up), updates the thermal model (each
 * heater's power read from its timer's PWM registers, pwm.c: the compare output's
 * duty while connected, else the pin's port bit)
 * and watches for timer compare interrupts that simavr lost (flag, enable and
 * I set, vector not queued): it queues them again and counts every repair.
 * The executed-segment record is built from pin edges: step/dir give the
 * physical steps, MARK_EDGE (a timer compare output) the segment ends and the
 * starts and stops of motion, hence the motion clock. */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <pty.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_interrupts.h>
#include <sim_io.h>
#include <sim_irq.h>
#include <sim_cycle_timers.h>
#include <avr_adc.h>
#include <avr_extint.h>
#include <avr_ioport.h>
#include <avr_uart.h>

#include "mailbox_layout.h"
#include "overflow_compares.h"
#include "pins.h"
#include "thermal.h"

#define F_CPU 16000000ULL
#define CLOCK_HZ 100000ULL /* the protocol clock: record times are in its units */
#define UNIT_CYCLES (F_CPU / CLOCK_HZ)
#define POLL_US 500

static avr_t *avr;
static volatile sig_atomic_t stop_flag;
static int master = -1, slave = -1;
static int exit_on_hangup, host_seen;
static double speedup = 1.0, time_limit = 0.0;
static struct timespec wall0;

/* bytes host -> AVR and AVR -> host */
static uint8_t in_buf[65536];
static size_t in_len, in_pos;
static uint8_t *out_buf;
static size_t out_len, out_cap;
static int xon = 1;
static avr_irq_t *uart_in;

/* motion record from pins */
static int dir_level[4];
static int64_t phys[4];        /* steps counted from the pins since boot */
static int64_t offset[4];      /* logical = phys + offset */
static int64_t boot_physical = -8000;
static int endstop_level[3] = {-1, -1, -1};
static avr_irq_t *endstop_irq[3];
static uint64_t motion_units, motion_since; /* whole motion periods, in clock units */
static int motion_level;
static int abort_next;
static FILE *record;
static char *record_path, *stats_path;
static uint32_t mailbox_addr;
static uint64_t segments_recorded;
static unsigned motion_clock_slips; /* segment ends where the edge clock disagreed */

/* step timing figures */
static uint64_t last_rise[4], last_dir_change[4], rise_at[4];
static uint64_t min_high = UINT64_MAX, min_low_gap = UINT64_MAX, min_dir_setup = UINT64_MAX;
static uint64_t steps_total;

/* lost interrupt repair */
static unsigned repairs, unrepaired;
static int suspect[2];

static uint32_t pc_hist[1 << 18]; /* per byte address of the 256 KB flash */
static uint64_t isr_entry, isr_cycles_max, isr_cycles_sum, isr_count, isr_hist[64];
static uint16_t isr_sp;
/* compare B interrupts outside compare A's (the steps it issues between ticks) */
static uint64_t b_entry, b_cycles_sum, b_count;
static uint16_t b_sp;
/* every step interrupt either engine uses, from its vector to its own RETI, counted once
 * when step interrupts nest (the outermost): Timer1 compare A (the tick) and B (the
 * DDA's steps between ticks), Timer3 compare A-C and Timer5 compare A (step_engine.c);
 * byte addresses of the ATmega2560's vectors, 4 bytes each */
static const uint16_t step_vectors[] = {17 * 4, 18 * 4, 32 * 4, 33 * 4, 34 * 4, 47 * 4};
static uint64_t step_entry, step_cycles_sum, step_cycles_max, step_count;
static uint16_t step_sp;
static uint32_t trace_pc[8192];
static size_t trace_len;
/* Debugging: every instruction (its address, its cycle; interrupts included) of a stretch
 * of the run, written to CDPR_SIM_LONG_TURN as "pc cycle" lines. The stretch: the
 * cycles CDPR_SIM_WINDOW="from,to" (CDPR_SIM_WINDOW_MOTION: counted from the first start of
 * motion, the step log's clock while motion has not paused); or the main loop's turn, from one call of the function
 * at CDPR_SIM_TURN_PC (hex byte address; one the loop calls once a turn at its top) to the
 * next: each new longest one, or (CDPR_SIM_TURN_STOP_PC) the one reaching that address,
 * up to it. */
#define TRACE_MAX (1u << 21)
static uint32_t *trace_at_pc, *trace_at_cycle;
static size_t trace_n;
static avr_flashaddr_t turn_top, turn_stop;
static avr_cycle_count_t turn_start, turn_longest, window_from, window_to;
static avr_cycle_count_t window_motion_from, window_motion_to; /* 0, 0: none */

static void trace_write(const char *path)
{
    FILE *f = fopen(path, "w");
    for (size_t i = 0; f && i < trace_n; i++)
        fprintf(f, "%x %u\n", trace_at_pc[i], trace_at_cycle[i]);
    if (f)
        fclose(f);
}

static void trace_add(avr_flashaddr_t pc, avr_cycle_count_t since)
{
    if (trace_n < TRACE_MAX) {
        trace_at_pc[trace_n] = pc;
        trace_at_cycle[trace_n++] = (uint32_t)since;
    }
}

static void trace_step(avr_flashaddr_t pc, avr_cycle_count_t cycle, const char *path)
{
    if (window_motion_to)
        return; /* the window is not placed yet */
    if (window_to) {
        if (cycle >= window_to) {
            window_to = 0;
            trace_write(path);
        } else if (cycle >= window_from) {
            trace_add(pc, cycle - window_from);
        }
        return;
    }
    if (turn_stop && pc == turn_stop) {
        turn_stop = 0;
        turn_longest = ~(avr_cycle_count_t)0; /* this one stays */
        trace_write(path);
    }
    if (pc == turn_top) {
        if (turn_start && cycle - turn_start > turn_longest) {
            turn_longest = cycle - turn_start;
            trace_write(path);
        }
        turn_start = cycle;
        trace_n = 0;
    }
    trace_add(pc, cycle - turn_start);
}

/* resets and the enable pins across them */
static volatile sig_atomic_t reset_request, watchdog_request;
static unsigned resets;
static int en_watch;             /* from a reset to the host's first byte after it */
static unsigned en_released_mask; /* enable pins seen high inside the last such window */
static unsigned en_high_mask;     /* enable pins high now */
static avr_flashaddr_t boot_pc;
static double smash_canary_after = -1.0; /* overwrite the stack canary then (sim seconds) */

static struct thermal thermal[2];
static double heater_power[2]; /* 0..1, as last read */
/* SIGUSR2's hang of the main loop: when it began (simulated s), and how long after it
 * both heaters were off (the heater lease's work, before the watchdog's) */
static double hang_at = -1.0, heaters_off_after_hang = -1.0, hang_after = -1.0;
static double heater_fail_after = -1.0;
static double sensor_fault_after = -1.0; /* the hotend's thermistor opens or shorts then */
static int sensor_fault = SENSOR_OK;
static double hotend_start_c = -1000.0; /* the hotend's temperature at power-on (warm start) */

static double sim_seconds(void) { return (double)avr->cycle / (double)F_CPU; }

static void on_signal(int sig) { (void)sig; stop_flag = 1; }
static void on_reset_signal(int sig) { (void)sig; reset_request = 1; }
static void on_watchdog_signal(int sig) { (void)sig; watchdog_request = 1; }

static uint32_t mailbox_u32(unsigned off)
{
    uint32_t v = 0;
    for (int i = 3; i >= 0; i--)
        v = (v << 8) | avr->data[mailbox_addr + off + i];
    return v;
}

static unsigned mailbox_u16(unsigned off)
{
    return avr->data[mailbox_addr + off] | (unsigned)avr->data[mailbox_addr + off + 1] << 8;
}

static void out_push(uint8_t b)
{
    if (out_len == out_cap) {
        out_cap = out_cap ? 2 * out_cap : 4096;
        out_buf = realloc(out_buf, out_cap);
        if (!out_buf) { perror("realloc"); exit(2); }
    }
    out_buf[out_len++] = b;
}

static void uart_out_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)param;
    out_push((uint8_t)value);
}

static void feed_uart(void)
{
    while (xon && in_pos < in_len) {
        uint8_t b = in_buf[in_pos++];
        avr_raise_irq(uart_in, b);
    }
    if (in_pos == in_len)
        in_pos = in_len = 0;
}

static void xon_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)value; (void)param;
    xon = 1;
    feed_uart();
}

static void xoff_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)value; (void)param;
    xon = 0;
}

/* Switches, as external drivers of their pins (simavr's "external pull" for that bit, so
 * that the firmware's pull-up and every later write to the same PORT register do not
 * override them; simavr re-asserts a pulled-up input high on each write). A module's
 * homing switch is pressed only at its flag, physical 0 .. HOME_SWITCH_BAND - 1 (the
 * carriage approaches it from below while homing and prints above it); its limit
 * switch (RAMPS MAX socket) is pressed past the end of travel, physical > travel_steps
 * (the Python model's overtravel_steps: 16400 by default). */
#define HOME_SWITCH_BAND 100
static int64_t travel_steps = 16400;
static int limit_level[3] = {-1, -1, -1};
static avr_irq_t *limit_irq[3];

static void drive_pin(const struct pin *pin, avr_irq_t *irq, int level)
{
    static uint8_t mask[256], value[256];
    uint8_t port = (uint8_t)pin->port, bit = (uint8_t)(1u << pin->bit);
    mask[port] |= bit;
    value[port] = (uint8_t)(level ? value[port] | bit : value[port] & ~bit);
    avr_ioport_external_t ext = {.name = (char)port, .mask = mask[port], .value = value[port]};
    avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(port), &ext);
    avr_raise_irq(irq, (uint32_t)level);
}

/* the switch levels driven again (poll): a write to the port's pull-up after the last
 * change would otherwise leave a released switch reading high */
static void redrive_switches(void)
{
    for (int k = 0; k < 3; k++) {
        if (endstop_level[k] >= 0)
            drive_pin(&ENDSTOP_PINS[k], endstop_irq[k], endstop_level[k]);
        if (limit_level[k] >= 0)
            drive_pin(&LIMIT_PINS[k], limit_irq[k], limit_level[k]);
    }
}

static void set_endstop(int k)
{
    int64_t at = phys[k] + boot_physical;
    int level = at >= 0 && at < HOME_SWITCH_BAND;
    if (level != endstop_level[k]) {
        endstop_level[k] = level;
        drive_pin(&ENDSTOP_PINS[k], endstop_irq[k], level);
    }
    level = at > travel_steps;
    if (level != limit_level[k]) {
        limit_level[k] = level;
        drive_pin(&LIMIT_PINS[k], limit_irq[k], level);
    }
}

/* CDPR_SIM_STEP_LOG=FILE: every rising step edge as "axis cycles", the cycles counted on
 * the motion clock (cycles of motion since boot: the record's t times 16e6), so the
 * benchmark can set each edge against the step's ideal time on its segment's profile.
 * An edge is written when its segment ends, timed back from that end on the firmware's
 * own motion clock (a segment runs without a pause, so the cycles between an edge and
 * its segment's end are the motion time between them). The edge clock of the markers
 * alone went wrong until the segment's end whenever a start or stop marker was lost
 * (an idle tick at rest whose markers a late computation missed: every edge of the next
 * segment one 400 us tick off). Edges no segment end claims (homing) keep the marker
 * clock, written when motion stops or the simulator exits. */
static FILE *step_log;
static uint64_t motion_now_cycles(uint64_t now);

struct logged_edge {
    uint64_t cycle;    /* the simulator's cycle of the rising edge */
    uint64_t fallback; /* the marker clock's motion time then (cycles) */
    int axis;
};
static struct logged_edge *edges_waiting;
static size_t edges_n, edges_cap;

static void log_step(int k, uint64_t now)
{
    if (!step_log)
        return;
    if (edges_n == edges_cap) {
        edges_cap = edges_cap ? 2 * edges_cap : 1024;
        edges_waiting = realloc(edges_waiting, edges_cap * sizeof *edges_waiting);
        if (!edges_waiting) {
            fprintf(stderr, "cdpr-sim: out of memory for the step log\n");
            exit(1);
        }
    }
    edges_waiting[edges_n++] = (struct logged_edge){now, motion_now_cycles(now), k};
}

/* Write the waiting edges: timed back from a segment end at motion time end_cycles
 * (the simulator's cycle end_at), or (end_at 0) on the marker clock. */
static void write_edges(uint64_t end_cycles, uint64_t end_at)
{
    for (size_t i = 0; i < edges_n; i++) {
        const struct logged_edge *e = &edges_waiting[i];
        uint64_t back = end_at - e->cycle;
        uint64_t t = end_at && e->cycle <= end_at && back <= end_cycles ? end_cycles - back
                                                                         : e->fallback;
        fprintf(step_log, "%d %llu\n", e->axis, (unsigned long long)t);
    }
    edges_n = 0;
}

static void step_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    value &= 1; /* a compare output also carries AVR_IOPORT_OUTPUT */
    (void)irq;
    int k = (int)(intptr_t)param;
    uint64_t now = avr->cycle;
    if (value) {
        if (last_rise[k] && now - last_rise[k] < min_low_gap)
            min_low_gap = now - last_rise[k];
        if (last_dir_change[k] && now - last_dir_change[k] < min_dir_setup)
            min_dir_setup = now - last_dir_change[k];
        last_dir_change[k] = 0;
        last_rise[k] = now;
        rise_at[k] = now;
        log_step(k, now);
        phys[k] += dir_level[k] ? 1 : -1;
        steps_total++;
        if (k < 3)
            set_endstop(k);
    } else if (rise_at[k]) {
        if (now - rise_at[k] < min_high)
            min_high = now - rise_at[k];
        rise_at[k] = 0;
    }
}

static void dir_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    value &= 1; /* a compare output also carries AVR_IOPORT_OUTPUT */
    (void)irq;
    int k = (int)(intptr_t)param;
    if ((int)value != dir_level[k]) {
        dir_level[k] = (int)value;
        last_dir_change[k] = avr->cycle;
    }
}

/* The motion clock, in clock units: the time between the MARK_EDGE toggles
 * that start and stop motion. The timer toggles MARK_EDGE exactly at tick
 * boundaries (one cycle in), so every period is a whole number of units. */
static uint64_t units_since(uint64_t since)
{
    return (avr->cycle - since + UNIT_CYCLES / 2) / UNIT_CYCLES;
}

static uint64_t motion_now_cycles(uint64_t now)
{
    return motion_units * UNIT_CYCLES + (motion_level ? now - motion_since : 0);
}

static uint64_t motion_now(void)
{
    return motion_units + (motion_level ? units_since(motion_since) : 0);
}

static const char *error_name(int code)
{
    static const char *names[] = {"error", "underrun", "thermal_runaway", "endstop_hit",
        "step_rate", "queue_overflow", "bad_command", "estop", "heater_range",
        "homing_failed", "overtemp"};
    return code > 0 && code <= 10 ? names[code] : "error";
}

/* The firmware's motion clock at the segment's end (ticks); the edge clock must agree (a
 * motion start or stop marker is lost when a tick's computation overran the boundary it
 * was due at): a slip is counted and the edge clock set right. */
static uint64_t segment_end_ticks(void)
{
    uint32_t fw = mailbox_u32(MB_MOTION_TICKS);
    uint64_t ticks = motion_now();
    int64_t slip = (int64_t)(int32_t)(fw - (uint32_t)ticks);
    if (slip) {
        motion_clock_slips++;
        motion_units = (uint64_t)((int64_t)motion_units + slip);
        ticks = (uint64_t)((int64_t)ticks + slip);
    }
    return ticks;
}

static void record_segment(uint64_t ticks)
{
    if (!record)
        return;
    uint32_t seq = mailbox_u32(MB_SEQ);
    fprintf(record, "{\"seq\":%u,\"steps\":[%lld,%lld,%lld,%lld],\"t\":%.6f", seq,
            (long long)(phys[0] + offset[0]), (long long)(phys[1] + offset[1]),
            (long long)(phys[2] + offset[2]), (long long)(phys[3] + offset[3]),
            (double)ticks / (double)CLOCK_HZ);
    if (abort_next)
        fprintf(record, ",\"error\":\"%s\"", error_name(avr->data[mailbox_addr + MB_LAST_ERROR]));
    fputs("}\n", record);
    fflush(record); /* streamed: a killed simulator leaves every line written so far */
    abort_next = 0;
    segments_recorded++;
}

/* A marker pin's level changed (a compare output also carries AVR_IOPORT_OUTPUT, so
 * only bit 0 counts); only toggles of a running firmware (its mailbox is known) count. */
static int toggled(uint32_t value, uint32_t *level)
{
    value &= 1;
    if (value == *level || !mailbox_addr)
        return 0;
    *level = value;
    return 1;
}

static int trace_motion; /* CDPR_SIM_TRACE_MOTION, read once at start */

/* MARK_EDGE toggled: the firmware left what it means in the mailbox. */
static void edge_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    static uint32_t level;
    (void)irq; (void)param;
    if (!toggled(value, &level))
        return;
    uint8_t edge = avr->data[mailbox_addr + MB_EDGE];
    if (trace_motion)
        fprintf(stderr, "edge %x at %llu\n", edge, (unsigned long long)avr->cycle);
    if ((edge & EDGE_MOTION_START) && !motion_level) {
        motion_since = avr->cycle;
        if (window_motion_to) {
            window_from = avr->cycle + window_motion_from;
            window_to = avr->cycle + window_motion_to;
            window_motion_to = 0;
            trace_n = 0;
        }
        motion_level = 1;
    }
    if (edge & EDGE_SEG_END) {
        uint64_t ticks = segment_end_ticks();
        if (step_log)
            write_edges(ticks * UNIT_CYCLES, avr->cycle);
        record_segment(ticks);
    }
    if ((edge & EDGE_MOTION_STOP) && motion_level) {
        motion_units += units_since(motion_since);
        motion_level = 0;
        if (step_log)
            write_edges(0, 0);
    }
}

static void abort_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    static uint32_t level;
    (void)irq; (void)param;
    if (!toggled(value, &level))
        return;
    abort_next = 1;
}

static void pos_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    static uint32_t level;
    (void)irq; (void)param;
    if (!toggled(value, &level))
        return;
    for (int k = 0; k < 4; k++)
        offset[k] = (int64_t)(int32_t)mailbox_u32(MB_POS + 4 * k) - phys[k];
}

/* The host watchdog seen from outside: the longest time a heater pin was high after the
 * host's last byte (the device's wall time, the clock of the firmware's link timers). */
static double last_host_byte_wall = -1.0, heater_on_silence_max;
static double wall_seconds(void);
static double device_seconds(void);

static void note_heater_silence(void)
{
    if (last_host_byte_wall < 0)
        return;
    double gap = device_seconds() - last_host_byte_wall;
    if (gap > heater_on_silence_max)
        heater_on_silence_max = gap;
}

/* A heater's power now: its timer's compare output drives the pin with the duty
 * OCR / 255 (phase-correct 8-bit PWM) while connected and the timer runs; else the
 * pin's port bit does (the shutdown path drives it directly). The firmware changes a
 * duty every control period (100 ms) at most, so reading it every poll is exact to
 * POLL_US; the PWM's own cycle (2 ms, 33 ms) averages out in the plant's 10 ms bins
 * and its seconds-long time constants. */
static double read_heater_power(const struct heater_pwm *p)
{
    const uint8_t *d = avr->data;
    if (!(d[p->ddr] & (1u << p->bit)))
        return 0.0;
    if ((d[p->tccr_a] & p->com) && (d[p->tccr_b] & 7))
        return (double)d[p->ocr] / 255.0;
    return (d[p->port] >> p->bit) & 1 ? 1.0 : 0.0;
}

static void sample_heaters(void)
{
    for (int h = 0; h < 2; h++) {
        double power = read_heater_power(&HEATER_PWM[h]);
        if (power != heater_power[h])
            thermal_switch(&thermal[h], sim_seconds(), power);
        heater_power[h] = power;
    }
    if (hang_at >= 0 && heaters_off_after_hang < 0 && heater_power[0] == 0.0 &&
        heater_power[1] == 0.0)
        heaters_off_after_hang = sim_seconds() - hang_at;
}

static void en_cb(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    unsigned bit = 1u << (int)(intptr_t)param;
    if (value & 1) {
        en_high_mask |= bit;
        if (en_watch)
            en_released_mask |= bit;
    } else {
        en_high_mask &= ~bit;
    }
}

static avr_irq_t *pin_irq(char port, int bit)
{
    return avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(port), bit);
}

static void watch(char port, int bit, avr_irq_notify_t cb, intptr_t param)
{
    avr_irq_register_notify(pin_irq(port, bit), cb, (void *)param);
}

static avr_int_vector_t *vector_no(int n)
{
    for (int i = 0; i < avr->interrupts.vector_count; i++)
        if (avr->interrupts.vector[i] && avr->interrupts.vector[i]->vector == n)
            return avr->interrupts.vector[i];
    return NULL;
}

/* A write to TIMSK1 that enables a Timer1 interrupt whose flag is already up queues it,
 * as silicon does (the flag is what requests the interrupt). simavr 1.6 queues an
 * interrupt only when its flag rises while enabled, so the firmware's "clear the flag,
 * set the compare, enable" raced a compare that matched in between: the step waited for
 * the next poll or tick (400-500 us late; seen once in CI). */
#define TIMSK1_ADDR 0x6F
#define TIFR1_ADDR 0x36
static unsigned enable_queued; /* interrupts queued by this hook (stats) */

/* The same for the step engine's timers (step_engine.c): Timer3's compares A-C (vectors
 * 32-34) and Timer5's A (47), whose interrupts a stepper's slow path masks while it
 * works and enables again. */
struct timer_irqs {
    uint8_t tifr;
    struct { int vec; uint8_t bit; } v[3];
};
static const struct timer_irqs timer1_irqs = {TIFR1_ADDR, {{17, 0x02}, {18, 0x04}, {19, 0x08}}};
static const struct timer_irqs timer3_irqs = {0x38, {{32, 0x02}, {33, 0x04}, {34, 0x08}}};
static const struct timer_irqs timer5_irqs = {0x3A, {{47, 0x02}, {0, 0}, {0, 0}}};

static void timsk_write(struct avr_t *a, avr_io_addr_t addr, uint8_t v, void *param)
{
    const struct timer_irqs *t = param;
    uint8_t was = a->data[addr];
    avr_core_watch_write(a, addr, v);
    uint8_t tifr = a->data[t->tifr];
    for (int i = 0; i < 3; i++) {
        if (!t->v[i].bit || !(v & t->v[i].bit) || (was & t->v[i].bit) || !(tifr & t->v[i].bit))
            continue;
        avr_int_vector_t *vec = vector_no(t->v[i].vec);
        if (vec && !avr_is_interrupt_pending(a, vec)) {
            avr_raise_interrupt(a, vec);
            enable_queued++;
            if (getenv("CDPR_SIM_TRACE_MOTION"))
                fprintf(stderr, "queued vector %d on enable at %llu\n", t->v[i].vec,
                        (unsigned long long)a->cycle);
        }
    }
}

/* Timer1 compare A (vector 17) and B (18): flag, enable and I set, not queued. */
static void check_lost_interrupts(void)
{
    static const struct { int vec; uint8_t bit; } t1[2] = {{17, 0x02}, {18, 0x04}};
    uint8_t tifr = avr->data[0x36], timsk = avr->data[0x6F];
    for (int i = 0; i < 2; i++) {
        avr_int_vector_t *v = vector_no(t1[i].vec);
        int lost = v && (tifr & t1[i].bit) && (timsk & t1[i].bit) && avr->sreg[S_I] &&
                   !avr_is_interrupt_pending(avr, v);
        if (!lost) {
            suspect[i] = 0;
            continue;
        }
        if (suspect[i])
            unrepaired++; /* still lost one poll after a repair */
        avr_raise_interrupt(avr, v);
        repairs++;
        suspect[i] = 1;
    }
}

static double wall_seconds(void)
{
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (double)(now.tv_sec - wall0.tv_sec) + 1e-9 * (double)(now.tv_nsec - wall0.tv_nsec);
}

/* The device's wall clock: wall time less the time this process was not running. A chip
 * never stops, but a simulator on a busy PC can be descheduled for seconds; the host's
 * bytes then wait in the pty, and if the device's clock counted that time its link timers
 * (the host watchdog: 2 s) would fire on a host that spoke all along. A poll comes every
 * POLL_US of simulated time (under a millisecond of wall time when running); a longer gap
 * is counted as MAX_POLL_GAP_S, so a stall is lost time for the device and for the host
 * alike, like a frozen link, never silence. */
#define MAX_POLL_GAP_S 0.05
static double device_wall, device_wall_seen, stalled_s;
static void advance_device_wall(void)
{
    /* a paced poll at a slow speed-up sleeps POLL_US / speedup: never a stall */
    double gap_max = fmax(MAX_POLL_GAP_S, 4e-6 * POLL_US / speedup);
    double now = wall_seconds(), dt = now - device_wall_seen;
    device_wall_seen = now;
    if (dt > gap_max) {
        stalled_s += dt - gap_max;
        dt = gap_max;
    }
    device_wall += dt;
}

static double device_seconds(void) { return device_wall; }

/* the most the simulation fell behind the device's wall clock (s): it then runs flat out
 * until it has caught up, faster than the device would */
static double behind_max;
static void pace(void)
{
    double ahead = sim_seconds() / speedup - device_seconds();
    if (-ahead > behind_max)
        behind_max = -ahead;
    if (ahead > 0.0005) {
        struct timespec d = {(time_t)ahead, (long)((ahead - floor(ahead)) * 1e9)};
        nanosleep(&d, NULL);
    }
}

static unsigned long polls;
static void poll_pty(void)
{
    polls++;
    if (in_len < sizeof in_buf) {
        ssize_t n = read(master, in_buf + in_len, sizeof in_buf - in_len);
        if (n > 0) {
            in_len += (size_t)n;
            if (!host_seen && exit_on_hangup && slave >= 0) {
                close(slave); /* from now on EIO means the host hung up */
                slave = -1;
            }
            host_seen = 1;
            en_watch = 0;
            last_host_byte_wall = device_seconds();
        } else if (n < 0 && errno == EIO && exit_on_hangup && host_seen) {
            stop_flag = 1;
        }
    }
    feed_uart();
    if (out_len) {
        ssize_t n = write(master, out_buf, out_len);
        if (n > 0) {
            memmove(out_buf, out_buf + n, out_len - (size_t)n);
            out_len -= (size_t)n;
        } else if (n < 0 && errno == EIO) {
            out_len = 0; /* nobody listens: a UART drops it too */
        } else if (n < 0 && getenv("CDPR_SIM_DEBUG")) {
            static int shown;
            if (shown++ < 3)
                fprintf(stderr, "cdpr-sim: write: %s (%zu pending)\n", strerror(errno), out_len);
        }
    }
}

/* simavr 1.6 keeps input voltages for ADC0..7 only (adc_values[8]): map the
 * thermistor channels ADC13 and ADC14 onto the slots of ADC5 and ADC6, whose
 * pins the RAMPS does not use as analog inputs. Newer simavr stores all 16. */
static int adc_slot[2] = {13, 14};

static void map_adc_channels(void)
{
    for (avr_io_t *io = avr->io_port; io; io = io->next) {
        if (!io->kind || strcmp(io->kind, "adc"))
            continue;
        avr_adc_t *adc = (avr_adc_t *)io;
        if (sizeof adc->adc_values / sizeof adc->adc_values[0] >= 16)
            return;
        avr_adc_mux_t m5 = AVR_ADC_SINGLE(5), m6 = AVR_ADC_SINGLE(6);
        adc->muxmode[32 + 13 - 8] = m5; /* MUX5:0 = 0b100101: ADC13 */
        adc->muxmode[32 + 14 - 8] = m6;
        adc_slot[0] = 5;
        adc_slot[1] = 6;
        return;
    }
}

static void update_thermal(void)
{
    double t = sim_seconds();
    if (heater_fail_after >= 0 && t >= heater_fail_after)
        thermal[0].element_ok = 0;
    if (sensor_fault_after >= 0 && t >= sensor_fault_after)
        thermal[0].sensor = sensor_fault;
    for (int h = 0; h < 2; h++) {
        thermal_advance(&thermal[h], t);
        avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + adc_slot[h]),
                      thermal_millivolts(&thermal[h]));
    }
}

/* UART0 without simavr's stdio echo and without its poll sleep (a usleep on every read of
 * an empty UCSR0A: the stk500v2 bootloader polls it in its wait, which then took minutes
 * of wall time instead of about 5 s); the INT pins without strict level triggering. */
static void uart_and_extint_setup(void)
{
    uint32_t flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    /* The endstop pins are also INT3/INT5 inputs. simavr polls a low level on
     * an INT pin every cycle (level-triggered mode, the reset default) even
     * with the interrupt disabled, and starts another poller on every low
     * write: that alone made the simulation run at a third of real time. */
    for (uint8_t i = 0; i < 8; i++)
        avr_extint_set_strict_lvl_trig(avr, i, 0);
}

/* The chip reset (by its watchdog, or by us): the firmware's mailbox is found again once
 * it announces it, motion has stopped, the enable pins are watched until the host's
 * next byte. */
static void after_reset(const char *why)
{
    fprintf(stderr, "cdpr-sim: reset (%s) at %.6f s, pc 0x%x\n", why, sim_seconds(), avr->pc);
    uart_and_extint_setup(); /* simavr's reset brought back its defaults */
    resets++;
    mailbox_addr = 0;
    en_released_mask = 0;
    if (motion_level) {
        motion_units += units_since(motion_since);
        motion_level = 0;
    }
    en_watch = 1;
}

/* RESET pulled low and released, or the watchdog's reset: SRAM keeps its content (as
 * on the chip), the registers and I/O start over, MCUSR says which (EXTRF 0x02, WDRF
 * 0x08); bytes in flight are lost. */
static void chip_reset(uint8_t mcusr, const char *why)
{
    size_t lo = 0x200, n = (size_t)avr->ramend + 1 - lo;
    uint8_t *keep = malloc(n);
    avr_cycle_count_t cycle = avr->cycle; /* simavr's reset zeroes it: the clocks go on */
    if (!keep) { perror("malloc"); exit(2); }
    memcpy(keep, avr->data + lo, n);
    avr_reset(avr);
    memcpy(avr->data + lo, keep, n);
    free(keep);
    avr->cycle = cycle;
    avr->data[0x54] = mcusr;
    in_pos = in_len = 0;
    xon = 1;
    after_reset(why);
}

/* Intel hex into flash; 0 on success */
static int load_hex(const char *path)
{
    FILE *f = fopen(path, "r");
    if (!f) { perror(path); return -1; }
    char line[600];
    uint32_t base = 0;
    int bad = 0;
    while (!bad && fgets(line, sizeof line, f)) {
        unsigned len, addr, type;
        if (line[0] != ':' || sscanf(line + 1, "%2x%4x%2x", &len, &addr, &type) != 3) continue;
        if (type == 1) break;
        if (type == 2 || type == 4) {
            unsigned hi;
            sscanf(line + 9, "%4x", &hi);
            base = type == 2 ? (uint32_t)hi << 4 : (uint32_t)hi << 16;
            continue;
        }
        if (type != 0) continue;
        for (unsigned i = 0; i < len; i++) {
            unsigned b;
            uint32_t at = base + addr + i;
            if (sscanf(line + 9 + 2 * i, "%2x", &b) != 1 || at > avr->flashend) { bad = 1; break; }
            avr->flash[at] = (uint8_t)b;
        }
    }
    fclose(f);
    return bad ? -1 : 0;
}

/* The main loop sent into the application's first "rjmp .-2" (avr-libc's
 * __stop_program) with interrupts on: they go on, nothing feeds the watchdog. */
static void hang_main_loop(void)
{
    for (uint32_t a = 0; a + 1 < 0x3E000; a += 2)
        if (avr->flash[a] == 0xFF && avr->flash[a + 1] == 0xCF) {
            avr->pc = a;
            break;
        }
    hang_at = sim_seconds();
    heaters_off_after_hang = -1.0;
}

static void poll_timer(struct avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)a; (void)param; (void)when;
    advance_device_wall();
    overflow_compares_poll(avr);
    if (reset_request) {
        reset_request = 0;
        chip_reset(0x02, "RESET pin");
    }
    /* a hang of the main loop (sent into an endless loop: the interrupts go on, the
     * watchdog is fed no more), then the watchdog's two time-outs a poll apart: its
     * interrupt when the firmware enabled it (WDIE), then the reset */
    static int watchdog_stage;
    if (watchdog_stage == 2) {
        watchdog_stage = 0;
        chip_reset(0x08, "watchdog");
    } else if (watchdog_stage == 1) {
        avr_int_vector_t *v = vector_no(12);
        if (v && (avr->data[0x60] & 0x40))
            avr_raise_interrupt(avr, v);
        watchdog_stage = 2;
    } else if (watchdog_request && avr->sreg[S_I]) { /* not inside an interrupt */
        watchdog_request = 0;
        hang_main_loop();
        watchdog_stage = 1;
    }
    /* --hang-main-after: the same hang, with no time-outs hurried: simavr's own
     * watchdog follows in its time (1 s) */
    if (hang_after >= 0 && sim_seconds() >= hang_after && avr->sreg[S_I]) {
        hang_after = -1.0;
        hang_main_loop();
    }
    if (!mailbox_addr) {
        uint32_t addr = avr->data[0x4A] | (uint32_t)avr->data[0x4B] << 8; /* GPIOR1, GPIOR2 */
        if (addr && avr->data[addr] == 'C' && avr->data[addr + 3] == 'R') {
            mailbox_addr = addr;
            unsigned s16 = (unsigned)(speedup * 16.0 + 0.5);
            avr->data[addr + MB_SPEEDUP_X16] = (uint8_t)s16;
            avr->data[addr + MB_SPEEDUP_X16 + 1] = (uint8_t)(s16 >> 8);
        }
    }
    poll_pty();
    if (mailbox_addr) {
        /* the link's clock for the firmware: the device's wall time in clock units */
        uint64_t u = (uint64_t)(device_seconds() * (double)CLOCK_HZ);
        for (int i = 0; i < 4; i++)
            avr->data[mailbox_addr + MB_LINK_CLOCK + i] = (uint8_t)(u >> (8 * i));
        avr->data[mailbox_addr + MB_LINK_VALID] = 1;
    }
    if (smash_canary_after >= 0 && mailbox_addr && sim_seconds() >= smash_canary_after) {
        unsigned at = mailbox_u16(MB_CANARY_AT); /* what an overflowing stack would do */
        avr->data[at] = 0;
        avr->data[at + 1] = 0;
        smash_canary_after = -1.0;
    }
    check_lost_interrupts();
    redrive_switches();
    if (heater_power[0] > 0.0 || heater_power[1] > 0.0)
        note_heater_silence(); /* on until now */
    sample_heaters();
    update_thermal();
    pace();
    if (time_limit > 0 && sim_seconds() >= time_limit)
        stop_flag = 1;
}

static void write_stats(void)
{
    if (!stats_path)
        return;
    FILE *f = fopen(stats_path, "w");
    if (!f)
        return;
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    double wall = (double)(now.tv_sec - wall0.tv_sec) + 1e-9 * (double)(now.tv_nsec - wall0.tv_nsec);
    unsigned isr_max = mailbox_addr ? mailbox_u16(MB_ISR_MAX) : 0;
    unsigned lost = mailbox_addr ? mailbox_u16(MB_LOST_STEPS) : 0;
    unsigned loop_us = mailbox_addr ? mailbox_u16(MB_LOOP_MAX_US) : 0;
    unsigned stalls = mailbox_addr ? mailbox_u16(MB_PLAN_STALLS) : 0;
    unsigned overruns = mailbox_addr ? mailbox_u16(MB_OVERRUNS) : 0;
    unsigned latency = mailbox_addr ? avr->data[mailbox_addr + MB_LATENCY_MAX] : 0;
    unsigned late = mailbox_addr ? mailbox_u16(MB_LATE_PULSES) : 0;
    unsigned stack_free = mailbox_addr ? mailbox_u16(MB_STACK_FREE) : 0;
    fprintf(f,
            "{\"sim_seconds\":%.6f,\"wall_seconds\":%.6f,\"cycles\":%llu,\"repairs\":%u,"
            "\"unrepaired\":%u,\"segments_recorded\":%llu,\"steps\":%llu,"
            "\"min_pulse_high_us\":%.3f,\"min_step_interval_us\":%.3f,\"min_dir_setup_us\":%.3f,"
            "\"isr_max_cycles\":%u,\"lost_steps\":%u,\"plan_stalls\":%u,\"overruns\":%u,\"late_pulses\":%u,\"tick_latency_max_cycles\":%u,\"main_loop_max_us\":%u,"
            "\"segments_parsed\":%u,\"isr_profiled_max_cycles\":%llu,\"isr_profiled_mean_cycles\":%.1f,\"hotend_c\":%.3f,\"bed_c\":%.3f,\"heater_on_silence_max_s\":%.4f,\"stack_free_bytes\":%u,\"motion_clock_slips\":%u,\"isr_profiled_count\":%llu,\"compare_b_outside_cycles\":%llu,\"compare_b_outside_count\":%llu,\"behind_wall_max_ms\":%.1f,\"resets\":%u,\"enable_released_mask\":%u,\"enable_high_mask\":%u,\"heaters_off_after_hang_s\":%.4f,"
            "\"step_isr_cycles\":%llu,\"step_isr_count\":%llu,\"step_isr_max_cycles\":%llu,"
            "\"overflow_compares_served\":%u,\"stalled_s\":%.3f}\n",
            sim_seconds(), wall, (unsigned long long)avr->cycle, repairs, unrepaired,
            (unsigned long long)segments_recorded, (unsigned long long)steps_total,
            min_high == UINT64_MAX ? -1.0 : (double)min_high / 16.0,
            min_low_gap == UINT64_MAX ? -1.0 : (double)min_low_gap / 16.0,
            min_dir_setup == UINT64_MAX ? -1.0 : (double)min_dir_setup / 16.0, isr_max, lost, stalls, overruns, late, latency,
            loop_us, mailbox_addr ? mailbox_u32(MB_SEGMENTS_PARSED) : 0, (unsigned long long)isr_cycles_max, isr_count ? (double)isr_cycles_sum / (double)isr_count : 0.0, thermal[0].temp, thermal[1].temp, heater_on_silence_max,
            stack_free,
            motion_clock_slips, (unsigned long long)isr_count, (unsigned long long)b_cycles_sum,
            (unsigned long long)b_count, behind_max * 1000.0, resets, en_released_mask, en_high_mask,
            heaters_off_after_hang, (unsigned long long)step_cycles_sum,
            (unsigned long long)step_count, (unsigned long long)step_cycles_max,
            overflow_compares_served, stalled_s);
    fclose(f);
}

static void usage(void)
{
    fprintf(stderr, "usage: cdpr-sim FIRMWARE.elf [--speedup X] [--record FILE] [--stats FILE] "
                    "[--time-limit S] [--exit-on-hangup] [--heater-fail-after S] "
                    "[--thermistor-open-after S] [--thermistor-short-after S] [--hotend-start-c C] "
                    "[--boot-physical STEPS] [--travel-steps STEPS] [--bootloader HEX] "
                    "[--smash-canary-after S] [--hang-main-after S]\n");
    exit(2);
}

int main(int argc, char **argv)
{
    const char *elf = NULL, *bootloader = NULL;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "--speedup") && i + 1 < argc) speedup = atof(argv[++i]);
        else if (!strcmp(a, "--record") && i + 1 < argc) record_path = argv[++i];
        else if (!strcmp(a, "--stats") && i + 1 < argc) stats_path = argv[++i];
        else if (!strcmp(a, "--time-limit") && i + 1 < argc) time_limit = atof(argv[++i]);
        else if (!strcmp(a, "--heater-fail-after") && i + 1 < argc) heater_fail_after = atof(argv[++i]);
        else if (!strcmp(a, "--hotend-start-c") && i + 1 < argc) hotend_start_c = atof(argv[++i]);
        else if (!strcmp(a, "--thermistor-open-after") && i + 1 < argc) { sensor_fault_after = atof(argv[++i]); sensor_fault = SENSOR_OPEN; }
        else if (!strcmp(a, "--thermistor-short-after") && i + 1 < argc) { sensor_fault_after = atof(argv[++i]); sensor_fault = SENSOR_SHORT; }
        else if (!strcmp(a, "--boot-physical") && i + 1 < argc) boot_physical = atoll(argv[++i]);
        else if (!strcmp(a, "--travel-steps") && i + 1 < argc) travel_steps = atoll(argv[++i]);
        else if (!strcmp(a, "--bootloader") && i + 1 < argc) bootloader = argv[++i];
        else if (!strcmp(a, "--smash-canary-after") && i + 1 < argc) smash_canary_after = atof(argv[++i]);
        else if (!strcmp(a, "--hang-main-after") && i + 1 < argc) hang_after = atof(argv[++i]);
        else if (!strcmp(a, "--exit-on-hangup")) exit_on_hangup = 1;
        else if (a[0] == '-') usage();
        else elf = a;
    }
    if (!elf || speedup <= 0)
        usage();

    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    /* simavr's loader talks on stdout ("Loaded N .text ..."): the pty path must be the
     * first thing a user sees, so that chatter is dropped (kept on stderr with CDPR_SIM_DEBUG) */
    int saved_stdout = dup(1);
    int quiet = getenv("CDPR_SIM_DEBUG") ? -1 : open("/dev/null", O_WRONLY);
    dup2(quiet >= 0 ? quiet : 2, 1);
    if (quiet >= 0)
        close(quiet);
    int bad = elf_read_firmware(elf, &fw);
    fflush(stdout);
    if (bad) {
        fprintf(stderr, "cdpr-sim: cannot read %s\n", elf);
        return 2;
    }
    avr = avr_make_mcu_by_name("atmega2560");
    if (!avr) {
        fprintf(stderr, "cdpr-sim: simavr has no atmega2560\n");
        return 2;
    }
    avr_init(avr);
    avr_load_firmware(avr, &fw);
    if (bootloader) {
        if (load_hex(bootloader)) {
            fprintf(stderr, "cdpr-sim: cannot load the bootloader %s\n", bootloader);
            return 2;
        }
        avr->fuse[AVR_FUSE_LOW] = 0xFF;
        avr->fuse[AVR_FUSE_HIGH] = 0xD8;
        avr->fuse[AVR_FUSE_EXT] = 0xFD;
        boot_pc = avr->reset_pc = 0x3E000;
        avr->pc = avr->reset_pc;
    }
    avr->data[0x54] = 0x01; /* MCUSR: PORF, a power-on */
    avr->frequency = F_CPU;
    avr->vcc = avr->avcc = avr->aref = 5000;
    avr->log = getenv("CDPR_SIM_DEBUG") ? LOG_TRACE : LOG_ERROR;
    trace_motion = getenv("CDPR_SIM_TRACE_MOTION") != NULL;
    fflush(stdout);
    dup2(saved_stdout, 1);
    close(saved_stdout);

    uart_and_extint_setup();
    uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out_cb, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), xon_cb, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), xoff_cb, NULL);

    avr_register_io_write(avr, TIMSK1_ADDR, timsk_write, (void *)&timer1_irqs);
    avr_register_io_write(avr, 0x71, timsk_write, (void *)&timer3_irqs); /* TIMSK3 */
    avr_register_io_write(avr, 0x73, timsk_write, (void *)&timer5_irqs); /* TIMSK5 */
    overflow_compares_init(avr); /* simavr's compares just after an overflow */
    for (int k = 0; k < 4; k++) {
        watch(STEP_PINS[k].port, STEP_PINS[k].bit, step_cb, k);
        watch(DIR_PINS[k].port, DIR_PINS[k].bit, dir_cb, k);
    }
    for (int k = 0; k < 3; k++) {
        endstop_irq[k] = pin_irq(ENDSTOP_PINS[k].port, ENDSTOP_PINS[k].bit);
        limit_irq[k] = pin_irq(LIMIT_PINS[k].port, LIMIT_PINS[k].bit);
    }
    watch(MARK_EDGE.port, MARK_EDGE.bit, edge_cb, 0);
    watch(MARK_POS.port, MARK_POS.bit, pos_cb, 0);
    watch(MARK_ABORT.port, MARK_ABORT.bit, abort_cb, 0);
    for (int k = 0; k < 4; k++)
        watch(EN_PINS[k].port, EN_PINS[k].bit, en_cb, k);
    en_watch = 1;
    map_adc_channels();
    thermal_init(&thermal[0], 0);
    thermal_init(&thermal[1], 1);
    if (hotend_start_c > -273.0)
        thermal[0].temp = hotend_start_c;
    for (int k = 0; k < 3; k++)
        set_endstop(k);

    if (getenv("CDPR_SIM_STEP_LOG"))
        step_log = fopen(getenv("CDPR_SIM_STEP_LOG"), "w");
    if (record_path) {
        record = fopen(record_path, "w");
        if (!record) { perror(record_path); return 2; }
    }
    char name[256];
    if (openpty(&master, &slave, name, NULL, NULL) < 0) { perror("openpty"); return 2; }
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    printf("%s\n", name);
    fflush(stdout);

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    sa.sa_handler = on_reset_signal;
    sigaction(SIGUSR1, &sa, NULL);
    sa.sa_handler = on_watchdog_signal;
    sigaction(SIGUSR2, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);

    clock_gettime(CLOCK_MONOTONIC, &wall0);
    /* The poll runs from the run loop at a cycle deadline rather than from a
     * simavr cycle timer: under UART traffic simavr 1.6 was seen to drop cycle
     * timers for good, which would stop the bridge. */
    const avr_cycle_count_t poll_cycles = F_CPU * POLL_US / 1000000ULL;
    avr_cycle_count_t next_poll = poll_cycles;
    int state = cpu_Running;
    int debug = getenv("CDPR_SIM_DEBUG") != NULL;
    int profile_isr = getenv("CDPR_SIM_PROFILE_ISR") != NULL;
    int profile_all = getenv("CDPR_SIM_PROFILE_ALL") != NULL;
    FILE *cli_log = getenv("CDPR_SIM_CLI_LOG") ? fopen(getenv("CDPR_SIM_CLI_LOG"), "w") : NULL;
    /* debugging: every 20 ms of simulated time, the device's wall clock, the link's
     * bytes waiting each way, the cycles run with interrupts masked, the hits of the PC at
     * CDPR_SIM_DBG_PC (hex byte address), the timers' enables and flags, u32 words of RAM
     * at CDPR_SIM_DBG_U32 (hex data addresses, comma-separated) and each vector's entries */
    FILE *dbg_log = getenv("CDPR_SIM_DBG_LOG") ? fopen(getenv("CDPR_SIM_DBG_LOG"), "w") : NULL;
    avr_flashaddr_t dbg_pc = getenv("CDPR_SIM_DBG_PC") ? (avr_flashaddr_t)strtoul(getenv("CDPR_SIM_DBG_PC"), NULL, 16) : 0;
    static uint32_t dbg_vec[64];
    /* samples a second (CDPR_SIM_DBG_HZ, 50 unless told) */
    unsigned dbg_hz = getenv("CDPR_SIM_DBG_HZ") ? (unsigned)atoi(getenv("CDPR_SIM_DBG_HZ")) : 50;
    if (!dbg_hz)
        dbg_hz = 50;
    uint64_t dbg_masked = 0, dbg_hits = 0, dbg_next = 0;
    avr_cycle_count_t cli_start = 0;
    avr_flashaddr_t cli_pc = 0;
    avr_flashaddr_t prev_pc = 0;
    const char *trace_path = getenv("CDPR_SIM_LONG_TURN");
    if (trace_path) {
        const char *e;
        if ((e = getenv("CDPR_SIM_TURN_PC")))
            turn_top = (avr_flashaddr_t)strtoul(e, NULL, 16);
        if ((e = getenv("CDPR_SIM_TURN_STOP_PC")))
            turn_stop = (avr_flashaddr_t)strtoul(e, NULL, 16);
        if ((e = getenv("CDPR_SIM_WINDOW"))) {
            unsigned long long from = 0, to = 0;
            sscanf(e, "%llu,%llu", &from, &to);
            window_from = from;
            window_to = to;
        }
        if ((e = getenv("CDPR_SIM_WINDOW_MOTION"))) {
            unsigned long long from = 0, to = 0;
            sscanf(e, "%llu,%llu", &from, &to);
            window_motion_from = from;
            window_motion_to = to;
        }
        trace_at_pc = malloc(TRACE_MAX * sizeof *trace_at_pc);
        trace_at_cycle = malloc(TRACE_MAX * sizeof *trace_at_cycle);
        if (!trace_at_pc || !trace_at_cycle)
            trace_path = NULL;
    }
    while (!stop_flag && state != cpu_Done && state != cpu_Crashed) {
        avr_flashaddr_t run_pc = avr->pc;
        avr_cycle_count_t run_cycle = avr->cycle;
        state = avr_run(avr);
        if (cli_log) { /* debugging: spans with interrupts masked, over 60 cycles */
            if (!avr->sreg[S_I]) {
                if (!cli_start) {
                    cli_start = avr->cycle;
                    cli_pc = avr->pc;
                }
            } else if (cli_start) {
                if (avr->cycle - cli_start > 60)
                    fprintf(cli_log, "%llu %llu %x %x\n", (unsigned long long)cli_start,
                            (unsigned long long)(avr->cycle - cli_start), cli_pc, avr->pc);
                cli_start = 0;
            }
        }
        if (avr->pc == boot_pc && prev_pc != boot_pc && avr->cycle > 16) {
            if (mailbox_addr) /* the chip reset itself (its watchdog) */
                after_reset("by itself");
        }
        if (debug) {
            if (avr->pc == 0 && prev_pc != 0)
                fprintf(stderr, "cdpr-sim: reset at %.6f s, from pc 0x%x, sp 0x%x\n", sim_seconds(),
                        prev_pc, avr->data[0x5D] | avr->data[0x5E] << 8);
        }
        prev_pc = avr->pc;
        if (dbg_log) {
            if (avr->pc < 57 * 4 && !(avr->pc & 3))
                dbg_vec[avr->pc / 4]++;
            if (!avr->sreg[S_I])
                dbg_masked += avr->cycle - run_cycle;
            if (avr->pc == dbg_pc)
                dbg_hits++;
            if (avr->cycle >= dbg_next) {
                dbg_next = avr->cycle + F_CPU / dbg_hz;
                fprintf(dbg_log, "%.3f %.3f xon=%d in=%zu out=%zu masked=%llu hits=%llu pc=%x T3=%02x/%02x T5=%02x/%02x UCSR0B=%02x v:", sim_seconds(), device_seconds(), xon, in_len - in_pos, out_len, (unsigned long long)dbg_masked, (unsigned long long)dbg_hits, avr->pc, avr->data[0x71], avr->data[0x38], avr->data[0x73], avr->data[0x3A], avr->data[0xC1]);
                static unsigned dbg_addr[8], dbg_naddr;
                static int dbg_addr_read;
                if (!dbg_addr_read) {
                    dbg_addr_read = 1;
                    const char *e = getenv("CDPR_SIM_DBG_U32");
                    while (e && *e && dbg_naddr < 8) {
                        char *end;
                        dbg_addr[dbg_naddr++] = (unsigned)strtoul(e, &end, 16);
                        e = *end ? end + 1 : end;
                    }
                }
                for (unsigned i = 0; i < dbg_naddr; i++) {
                    unsigned a = dbg_addr[i];
                    fprintf(dbg_log, " u%x=%lu", a, (unsigned long)(avr->data[a] | avr->data[a + 1] << 8 | (uint32_t)avr->data[a + 2] << 16 | (uint32_t)avr->data[a + 3] << 24));
                }
                for (int i = 0; i < 57; i++)
                    if (dbg_vec[i])
                        fprintf(dbg_log, " %d:%u", i, dbg_vec[i]);
                fprintf(dbg_log, "\n");
                fflush(dbg_log);
                memset(dbg_vec, 0, sizeof dbg_vec);
                dbg_masked = dbg_hits = 0;
            }
        }
        if (trace_path)
            trace_step(run_pc, run_cycle, trace_path);
        if (profile_all && run_pc < sizeof pc_hist / sizeof pc_hist[0])
            pc_hist[run_pc] += (uint32_t)(avr->cycle - run_cycle); /* where the cycles go */
        if (profile_isr) {
            /* cycles from the step timer's vector to its own RETI (the one executed
             * with the stack pointer it entered with; nested interrupts included) */
            uint16_t sp = (uint16_t)(avr->data[0x5D] | avr->data[0x5E] << 8);
            if (isr_entry && avr->pc < sizeof pc_hist / sizeof pc_hist[0])
                pc_hist[avr->pc]++;
            if (isr_entry && trace_len < sizeof trace_pc / sizeof trace_pc[0])
                trace_pc[trace_len++] = avr->pc | (uint32_t)(avr->data[0x84] | avr->data[0x85] << 8) << 16 ;
            int at_step_vector = 0;
            for (size_t i = 0; i < sizeof step_vectors / sizeof step_vectors[0]; i++)
                at_step_vector |= avr->pc == step_vectors[i];
            if (at_step_vector && !step_entry) {
                step_entry = avr->cycle;
                step_sp = sp;
            } else if (step_entry && sp == step_sp && avr->flash[avr->pc] == 0x18 &&
                       avr->flash[avr->pc + 1] == 0x95) {
                uint64_t c = avr->cycle - step_entry + 4;
                if (c > step_cycles_max)
                    step_cycles_max = c;
                step_cycles_sum += c;
                step_count++;
                step_entry = 0;
            }
            if (avr->pc == 0x48 && !isr_entry && !b_entry) {
                b_entry = avr->cycle;
                b_sp = sp;
            } else if (b_entry && sp == b_sp && avr->flash[avr->pc] == 0x18 &&
                       avr->flash[avr->pc + 1] == 0x95) {
                b_cycles_sum += avr->cycle - b_entry + 4;
                b_count++;
                b_entry = 0;
            }
            if (avr->pc == 0x44 && !isr_entry) {
                isr_entry = avr->cycle;
                isr_sp = sp;
            } else if (isr_entry && sp == isr_sp && avr->flash[avr->pc] == 0x18 &&
                       avr->flash[avr->pc + 1] == 0x95) {
                uint64_t c = avr->cycle - isr_entry + 4;
                if (c > isr_cycles_max)
                    isr_cycles_max = c;
                isr_cycles_sum += c;
                isr_count++;
                isr_hist[c / 100 < 63 ? c / 100 : 63]++;
                isr_entry = 0;
                static long trace_lo = -1;
                if (trace_lo < 0)
                    trace_lo = getenv("CDPR_SIM_TRACE_AT") ? atol(getenv("CDPR_SIM_TRACE_AT")) : 0;
                int take = trace_lo ? (c >= (uint64_t)trace_lo && c < (uint64_t)trace_lo + 100)
                                    : (c > 1600 && c >= isr_cycles_max);
                if (take) {
                    if (trace_lo)
                        trace_lo = 1; /* the first one only */
                    /* the first over-long tick: its instruction trace, for the profile */
                    const char *isr_path = getenv("CDPR_SIM_LONG_ISR");
                    FILE *f = fopen(isr_path ? isr_path : "/tmp/cdpr-long-isr.txt", "w");
                    for (size_t i = 0; f && i < trace_len; i++)
                        fprintf(f, "%x %u\n", trace_pc[i] & 0xFFFF, trace_pc[i] >> 16);
                    if (f)
                        fclose(f);

                }
                trace_len = 0;
            }
        }
        if (avr->cycle >= next_poll) {
            poll_timer(avr, avr->cycle, NULL);
            next_poll += poll_cycles;
        }
    }
    if (record)
        fclose(record);
    if (step_log) {
        write_edges(0, 0);
        fclose(step_log);
    }
    write_stats();
    if (getenv("CDPR_SIM_PEEK")) { /* debugging: N uint16 at a data address, to a file */
        unsigned addr = 0, n = 0;
        sscanf(getenv("CDPR_SIM_PEEK"), "%x,%u", &addr, &n);
        FILE *f = fopen("/tmp/cdpr-peek.txt", "w");
        for (unsigned i = 0; f && i < n && addr + 2 * i + 1 < avr->ramend; i++)
            fprintf(f, "%u ", avr->data[addr + 2 * i] | avr->data[addr + 2 * i + 1] << 8);
        if (f)
            fclose(f);
    }
    if (getenv("CDPR_SIM_PROFILE_ISR") || profile_all) {
        const char *hist_path = getenv("CDPR_SIM_PC_HIST");
        FILE *f = fopen(hist_path ? hist_path : "/tmp/cdpr-pc-hist.txt", "w");
        for (unsigned i = 0; f && i < sizeof pc_hist / sizeof pc_hist[0]; i++)
            if (pc_hist[i])
                fprintf(f, "%x %u\n", i, pc_hist[i]);
        if (f)
            fclose(f);
        for (int i = 0; i < 64; i++)
            if (isr_hist[i])
                fprintf(stderr, "isr %4d-%4d cycles: %llu\n", i * 100, i * 100 + 99,
                        (unsigned long long)isr_hist[i]);
    }
    if (getenv("CDPR_SIM_DEBUG"))
        fprintf(stderr, "cdpr-sim: pc 0x%x I=%d TIMSK1=%02x TIFR1=%02x UCSR0B=%02x out_len=%zu in_len=%zu xon=%d polls=%lu\n", avr->pc, avr->sreg[S_I], avr->data[0x6F], avr->data[0x36], avr->data[0xC1], out_len, in_len - in_pos, xon, polls);
    fprintf(stderr,
            "cdpr-sim: %.3f s simulated, %u interrupts queued on enable, %u lost interrupts "
            "repaired, %u unrepaired%s\n",
            sim_seconds(), enable_queued, repairs, unrepaired, state == cpu_Crashed ? ", CPU CRASHED" : "");
    return state == cpu_Crashed ? 3 : 0;
}
