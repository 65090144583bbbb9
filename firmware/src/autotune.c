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
} tu;

int8_t autotune_heater(void)
{
    return tu.state == AT_RUN ? (int8_t)tu.id : -1;
}

uint8_t autotune_relay(int16_t temp_dc, uint32_t now)
{
    if (tu.state != AT_RUN)
        return 0;
    if (temp_dc > tu.target + TUNE_OVERSHOOT_DC) {
        tu.failure = FAIL_OVERSHOOT;
        tu.state = AT_FAILED;
        return 0;
    }
    if (now - tu.t0 > TUNE_TIMEOUT_TICKS) {
        tu.failure = FAIL_TIMEOUT;
        tu.state = AT_FAILED;
        return 0;
    }
    if (temp_dc > tu.hi)
        tu.hi = temp_dc;
    if (temp_dc < tu.lo)
        tu.lo = temp_dc;
    if (now - tu.t_switch < RELAY_MIN_HOLD_TICKS) {
        /* hold */
    } else if (tu.heating && temp_dc > tu.target) {
        tu.heating = 0;
        tu.t_switch = now;
    } else if (!tu.heating && temp_dc < tu.target) {
        tu.heating = 1;
        if (tu.counting) { /* a whole cycle since the last switch-on */
            tu.period_sum += now - tu.t_on;
            tu.swing_sum += tu.hi - tu.lo;
            tu.n++;
        }
        tu.counting = 1;
        tu.t_on = tu.t_switch = now;
        tu.hi = tu.lo = temp_dc;
        if (tu.n >= tu.cycles) {
            if (tu.swing_sum <= 0 || !tu.period_sum) {
                tu.failure = FAIL_NO_OSCILLATION;
                tu.state = AT_FAILED;
            } else {
                tu.state = AT_DONE;
            }
            return 0;
        }
    }
    return tu.heating ? 255 : 0;
}

void autotune_cancel(void)
{
    if (tu.state == AT_IDLE)
        return;
    tu.state = AT_IDLE;
    heater_set_target(tu.id, 0, 0);
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

void autotune_poll(uint32_t now)
{
    uint8_t s = SREG;
    cli();
    uint8_t current = st.current;
    uint32_t items = st.items_done, segs = st.segments_done;
    SREG = s;
    if (current == IT_TUNE && tu.state == AT_IDLE && items + 1 != tu.item) {
        /* the AUTOTUNE item at the tail began executing (it keeps its slot) */
        const struct item *it = queue_slot(queue_tail);
        tu.state = AT_RUN;
        tu.item = items + 1;
        tu.id = it->u.tune.id & 1;
        tu.cycles = it->u.tune.cycles;
        tu.target = (int16_t)it->u.tune.target;
        tu.n = tu.counting = tu.failure = 0;
        tu.heating = 1;
        tu.hi = INT16_MIN;
        tu.lo = INT16_MAX;
        tu.t0 = tu.t_on = tu.t_switch = now;
        tu.period_sum = 0;
        tu.swing_sum = 0;
        heater_set_target(tu.id, (uint16_t)tu.target, now);
        return;
    }
    if (tu.state == AT_DONE) {
        float a = (float)tu.swing_sum / (20.0f * tu.n);                /* C */
        float period = (float)tu.period_sum / ((float)CLOCK_HZ * tu.n); /* s */
        float kp = 0.6f * 4.0f * 127.5f / (3.14159265f * a);
        int32_t v[4] = {tu.id, wire(kp), wire(2.0f * kp / period), wire(kp * period / 8.0f)};
        autotune_cancel();
        heater_set_pid(tu.id, (uint32_t)v[1], (uint32_t)v[2], (uint32_t)v[3]);
        upper->event(EVT_AUTOTUNE_DONE, tu.item, 4, v);
        stepper_wait_ok = 1; /* the item completes: the queue goes on */
    } else if (tu.state == AT_FAILED) {
        autotune_cancel();
        upper->fail(ERR_AUTOTUNE_FAILED, items, segs, tu.id, tu.failure);
    }
}
