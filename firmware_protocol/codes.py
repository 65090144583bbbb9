"""Numeric codes of the protocol: status flags, errors, events, boot causes, e-stop flags."""

from __future__ import annotations

from enum import IntEnum, IntFlag


class Flag(IntFlag):
    MOVING = 0x01
    FAULT = 0x02
    ESTOP = 0x04
    HOMED = 0x08
    ENABLED = 0x10
    HEATING = 0x20
    SYNCED = 0x40
    WAITING = 0x80


#: ``STEP_RATE``'s axis for the four axes' peak rates summed over ``STEP_BUDGET``'s total
#: (3.3)
ALL_AXES = 4


class ErrorCode(IntEnum):
    UNDERRUN = 1
    THERMAL_RUNAWAY = 2
    ENDSTOP_HIT = 3
    STEP_RATE = 4
    QUEUE_OVERFLOW = 5
    BAD_COMMAND = 6
    ESTOP = 7
    HEATER_RANGE = 8
    HOMING_FAILED = 9
    OVERTEMP = 10
    WATCHDOG = 11
    BAD_VALUE = 12
    # protocol 2.1
    PLANNER_LATE = 13  # segment preparation missed its start (not a step-rate excess)
    HEATER_LEASE = 14  # the host's heater lease ran out with a heater on
    AUTOTUNE_FAILED = 15  # PID autotune gave up (value: AutotuneFailure)
    STACK_OVERFLOW = 16  # the canary word below the stack was overwritten


#: faults a host must not clear on its own (the heater or its sensor needs a look first);
#: a 2.1 device latches them until a reset
THERMAL_ERRORS = frozenset({ErrorCode.THERMAL_RUNAWAY, ErrorCode.OVERTEMP})
#: faults whose shutdown switches the heaters off (the others leave them to the host, whose
#: watchdog and heater lease still guard them)
HEATERS_OFF = THERMAL_ERRORS | {
    ErrorCode.ESTOP,
    ErrorCode.WATCHDOG,
    ErrorCode.HEATER_LEASE,
    ErrorCode.AUTOTUNE_FAILED,
}


class EventCode(IntEnum):
    HOMED = 1
    HEATER_REACHED = 2
    FAULT_CLEARED = 3
    # protocol 2.1
    CLEAR_REFUSED = 4  # CLEAR_FAULT refused: values (the latched ErrorCode,)
    AUTOTUNE_DONE = 5  # values (heater, kp, ki, kd) in thousandths (gains already applied)


class AutotuneFailure(IntEnum):
    """``Error.value`` of ``AUTOTUNE_FAILED``."""

    TIMEOUT = 1  # no complete cycle within the time allowed
    OVERSHOOT = 2  # the temperature went more than 20 C over the target
    NO_OSCILLATION = 3  # the heater could not swing around the target (too weak or too slow)


class BootCause(IntEnum):
    POWER_ON = 0
    WATCHDOG = 1
    SOFT_RESET = 2
    EXTERNAL_RESET = 3  # the RESET pin: a button, or the DTR auto-reset of opening the port
    BROWN_OUT = 4


class EstopFlag(IntFlag):
    """``EmergencyStop.flags``: the heaters go off unless KEEP_HEATERS; the motors stay
    enabled (a cable robot must not drop its effector) unless RELEASE_MOTORS asks for it.
    KEEP_MOTORS is what every stop does now; it is still accepted."""

    KEEP_HEATERS = 0x01
    KEEP_MOTORS = 0x02
    RELEASE_MOTORS = 0x04
