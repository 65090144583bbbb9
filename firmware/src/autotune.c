/* AUTOTUNE: Marlin's M303 relay autotune (Astrom-Hagglund), as the Python model's
 * RelayTune does. The heater runs at full power below the target and off above it;
 * every switch back to heating after the first one closes a cycle with its period
 * and its swing (peak to peak / 2); each state holds for at least 5 s. After `cycles` of them the classic
 * Ziegler-Nichols gains from their means: Ku = 4 d / (pi a) with d = 255 / 2 the
 * relay's half swing, kp = 0.6 Ku, ki = 2 kp / Tu, kd = kp Tu / 8 (Marlin's units:
 * output 0..255, error in C, time in s). They are applied (as SET_PID would), the
 * heater goes off and EVENT AUTOTUNE_DONE reports them in thousandths.
 *
 * The AUTOTUNE item holds the queue as WAIT_HEATER does: the interrupt keeps it
 * executing until stepper_wait_ok. The heater's target is the tune's target all
 * along, so thermal protection, the heater lease and the watchdog apply as to any
 * heating; every fault goes through machine_shutdown, which cancels the tune and
 * switches its heater off. */
#include <avr/interrupt.h>
#include <stdint.h>

#include "autotune.h"
#include "config.h"
#include "heater.h"
#include "protocol_gen.h"
#include "queue.h"
#include "sched.h"
#include "stepper.h"

#define TUNE_TIMEOUT_TICKS (20UL * 60UL * CLOCK_HZ) /* 20 min */
#define TUNE_OVERSHOOT_DC 200                        /* 20 C over the target */
/* each relay state holds at least 5 s, so that the thermistor's noise around the
 * target cannot chatter it (Marlin's M303 waits as long; RELAY_MIN_HOLD_S in Python) */
#define RELAY_MIN_HOLD_TICKS (5UL * CLOCK_HZ)

enum { AT_IDLE, AT_RUN, AT_DONE, AT_FAILED };
enum { FAIL_TIMEOUT = 1, FAIL_OVERSHOOT = 2, FAIL_NO_OSCILLATION = 3 };

static struct {
    uint8_t state, id, cycles, n;
    uint8_t heating, counting; /* relay on; a switch-on after the first rise was seen */
    uint8_t failure;
    int16_t target, hi, lo;
    uint32_t item;             /* the AUTOTUNE item's number */
    uint32_t t0, t_on, t_switch;
    uint32_t period_sum;       /* clock ticks */
    int32_t swing_sum;         /* 0.1 C, peak to peak */
} tune;

int8_t autotune_heater(void)
{
    return tune.state == AT_RUN ? (int8_t)tune.id : -1;
}

uint8_t autotune_relay(int16_t temp_dc, uint32_t now)
{
    if (tune.state != AT_RUN)
        return 0;
    if (temp_dc > tune.target + TUNE_OVERSHOOT_DC) {
        tune.failure = FAIL_OVERSHOOT;
        tune.state = AT_FAILED;
        return 0;
    }
    if (now - tune.t0 > TUNE_TIMEOUT_TICKS) {
        tune.failure = FAIL_TIMEOUT;
        tune.state = AT_FAILED;
        return 0;
    }
    if (temp_dc > tune.hi)
        tune.hi = temp_dc;
    if (temp_dc < tune.lo)
        tune.lo = temp_dc;
    if (now - tune.t_switch < RELAY_MIN_HOLD_TICKS) {
        /* hold */
    } else if (tune.heating && temp_dc > tune.target) {
        tune.heating = 0;
        tune.t_switch = now;
    } else if (!tune.heating && temp_dc < tune.target) {
        tune.heating = 1;
        if (tune.counting) { /* a whole cycle since the last switch-on */
            tune.period_sum += now - tune.t_on;
            tune.swing_sum += tune.hi - tune.lo;
            tune.n++;
        }
        tune.counting = 1;
        tune.t_on = tune.t_switch = now;
        tune.hi = tune.lo = temp_dc;
        if (tune.n >= tune.cycles) {
            if (tune.swing_sum <= 0 || !tune.period_sum) {
                tune.failure = FAIL_NO_OSCILLATION;
                tune.state = AT_FAILED;
            } else {
                tune.state = AT_DONE;
            }
            return 0;
        }
    }
    return tune.heating ? 255 : 0;
}

void autotune_cancel(void)
{
    if (tune.state == AT_IDLE)
        return;
    tune.state = AT_IDLE;
    heater_set_target(tune.id, 0, 0);
}

/* thousandths on the wire, within the EVENT's signed values */
static int32_t wire(float x)
{
    x = x * 1000.0f + 0.5f;
    return x > 2.0e9f ? 2000000000L : (int32_t)x;
}

static const struct autotune_upper *upper;

void autotune_attach(const struct autotune_upper *u)
{
    upper = u;
}

/* The kind of the executing item and the progress counts (a frame of its own: the
 * snapshot is not on the stack under a fault's shutdown path). */
static uint8_t __attribute__((noinline)) executing(uint32_t *items, uint32_t *segs)
{
    struct stepper_progress done;
    stepper_progress(&done);
    *items = done.items_done;
    *segs = done.segments_done;
    return done.current;
}

static void __attribute__((noinline)) autotune_step(uint32_t now)
{
    uint32_t items, segs;
    uint8_t current = executing(&items, &segs);
    if (current == IT_TUNE && tune.state == AT_IDLE && items + 1 != tune.item) {
        /* the AUTOTUNE item at the tail began executing (it keeps its slot) */
        const struct item *it = queue_slot(queue_tail);
        tune.state = AT_RUN;
        tune.item = items + 1;
        tune.id = it->u.tune.id & 1;
        tune.cycles = it->u.tune.cycles;
        tune.target = (int16_t)it->u.tune.target;
        tune.n = tune.counting = tune.failure = 0;
        tune.heating = 1;
        tune.hi = INT16_MIN;
        tune.lo = INT16_MAX;
        tune.t0 = tune.t_on = tune.t_switch = now;
        tune.period_sum = 0;
        tune.swing_sum = 0;
        heater_set_target(tune.id, (uint16_t)tune.target, now);
        return;
    }
    if (tune.state == AT_DONE) {
        float a = (float)tune.swing_sum / (20.0f * tune.n);                /* C */
        float period = (float)tune.period_sum / ((float)CLOCK_HZ * tune.n); /* s */
        float kp = 0.6f * 4.0f * 127.5f / (3.14159265f * a);
        int32_t v[4] = {tune.id, wire(kp), wire(2.0f * kp / period), wire(kp * period / 8.0f)};
        autotune_cancel();
        heater_set_pid(tune.id, (uint32_t)v[1], (uint32_t)v[2], (uint32_t)v[3]);
        upper->event(EVT_AUTOTUNE_DONE, tune.item, 4, v);
        stepper_wait_ok = 1; /* the item completes: the queue goes on */
    } else if (tune.state == AT_FAILED) {
        autotune_cancel();
        upper->fail(ERR_AUTOTUNE_FAILED, items, segs, tune.id, tune.failure);
    }
}

void autotune_poll(uint32_t now)
{
    /* every main-loop turn, and nearly always nothing to do (autotune_step's frame and its
     * progress read cost each turn about 90 cycles): while idle, unless the item executing
     * (at the queue's tail, which keeps its slot) is an AUTOTUNE; while running, the
     * heater's hooks do the work */
    if (tune.state == AT_RUN ||
        (tune.state == AT_IDLE &&
         (queue_head == queue_tail || queue_slot(queue_tail)->kind != IT_TUNE)))
        return;
    autotune_step(now);
}
