"""A device stopped by a fault, in words, and the one refusal every command to it gets.

A faulted device discards what it is sent until the fault is cleared (PROTOCOL.md 6 and
7): a command sent anyway would be "done" without anything happening. So every operation
of :class:`~cdprhost.machine.operations.Machine` (home, heaters, drivers, moves: the
console, jog, calibration and a print start all use them) asks the device first and
refuses with :class:`DeviceFaulted`, naming the fault and the way out.
"""

from __future__ import annotations

from cdprhost.errors import CdprError
from cdprhost.link.events import DeviceStatus
from firmware_protocol.messages import THERMAL_ERRORS, ErrorCode

WHY = {
    ErrorCode.WATCHDOG: "its host stopped answering",
    ErrorCode.UNDERRUN: "its move queue ran empty while moving",
    ErrorCode.ESTOP: "emergency stop",
    ErrorCode.ENDSTOP_HIT: "an endstop was hit during motion",
    ErrorCode.STEP_RATE: "a step rate over its limit",
    ErrorCode.BAD_COMMAND: "a malformed command",
    ErrorCode.BAD_VALUE: "a command value out of range",
    ErrorCode.HEATER_RANGE: "a heater target over its maximum",
    ErrorCode.HOMING_FAILED: "homing failed",
    ErrorCode.QUEUE_OVERFLOW: "its queue overflowed",
}

CLEAR_HINT = (
    "M999 clears it: the device leaves its fault state, nothing queued before the fault "
    "runs again and the heaters stay off until set again (home with G28 if the motors "
    "were released)"
)
THERMAL_HINT = (
    "a thermal fault stays until the device is reset: check the heater and its sensor, "
    "then power-cycle the device"
)


class DeviceFaulted(CdprError):
    """A command asked of a device stopped by a fault: refused, nothing was sent."""


def fault_name(code: int) -> str:
    try:
        return ErrorCode(code).name.lower()
    except ValueError:
        return f"error {code}"


def fault_why(code: int) -> str:
    """What the fault means, in words ("" for a code without a story)."""
    return WHY.get(ErrorCode(code), "") if code in ErrorCode._value2member_map_ else ""


def describe_fault(st: DeviceStatus) -> str | None:
    """The device's fault in words (None when it is not faulted): what, why, where it stopped."""
    if not st.faulted:
        return None
    code = st.last_error
    name, why = fault_name(code), fault_why(code)
    # "watchdog: its host stopped answering", never "watchdog: ... (watchdog)"
    text = f"the device is stopped by a fault ({name}{': ' + why if why and why != name else ''})"
    return f"{text} after segment {st.segments_done}"


def fault_clearable(st: DeviceStatus) -> bool:
    """A host may clear it (thermal faults need the heater checked and a power cycle)."""
    return not (st.faulted and st.last_error in THERMAL_ERRORS)


def refusal(fault: str, clearable: bool) -> str:
    """The answer to a command for a faulted device: the fault and the way out."""
    return f"refused, nothing sent: {fault}; {CLEAR_HINT if clearable else THERMAL_HINT}"
