#include <avr/interrupt.h>

#include "heater.h"
#include "machine.h"
#include "protocol_gen.h"
#include "queue.h"
#include "reports.h"
#include "stepper.h"
#include "mailbox.h"

struct machine mc;

uint8_t machine_free(void)
{
    return queue_free();
}

uint8_t machine_flags(void)
{
    uint8_t f = 0;
    if (stepper_moving())
        f |= FLAG_MOVING;
    if (mc.fault)
        f |= FLAG_FAULT;
    if (mc.estopped)
        f |= FLAG_ESTOP;
    if ((st.homed_mask & 7) == 7)
        f |= FLAG_HOMED;
    if (st.enabled_mask)
        f |= FLAG_ENABLED;
    if (heaters[0].target_dc || heaters[1].target_dc)
        f |= FLAG_HEATING;
    if (st.current == IT_WAIT)
        f |= FLAG_WAITING;
    return f;
}

void machine_fail(uint8_t code, uint32_t item, uint32_t segment, uint8_t axis, int32_t value)
{
    sim_mailbox.last_error = code; /* before the abort marker names it */
    stepper_halt();
    mc.fault = code;
    mc.last_error = code;
    stepper_flush(mc.items_received);
    if (code == ERR_THERMAL_RUNAWAY || code == ERR_OVERTEMP || code == ERR_ESTOP) {
        heater_all_off();
        cli();
        st.heater_target[0] = st.heater_target[1] = 0;
        st.heater_target_changed = 0;
        sei();
    }
    report_error(code, item, segment, axis, value);
}

uint8_t machine_clear_fault(void)
{
    if (!mc.fault)
        return 0;
    mc.fault = 0;
    mc.estopped = 0;
    cli();
    stepper_report.error = 0;
    sei();
    stepper_resume();
    return 1;
}

void machine_estop(void)
{
    machine_fail(ERR_ESTOP, st.items_done, st.segments_done, 0xFF, 0);
    mc.estopped = 1;
    stepper_disable_all();
}
