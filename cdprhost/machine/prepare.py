"""Before a job uses a machine: read what the device is doing and make it ready, or refuse.

A device keeps its state across sessions (PROTOCOL.md 3.4): a fault from a host that
vanished (the watchdog), motion still queued by a killed host, heaters left on. The
job reads the status first, says what it found, and clears it explicitly: motion of an
earlier session is stopped (e-stop keeping heaters and motors), a fault is cleared.
Thermal faults are not cleared by a host: the job refuses with a clear message.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from cdprhost.errors import CdprError
from cdprhost.link.events import DeviceStatus
from cdprhost.machine.operations import ALL_MODULES, Machine
from firmware_protocol.messages import THERMAL_ERRORS, ErrorCode, EstopFlag

log = logging.getLogger(__name__)

_WHY = {
    ErrorCode.WATCHDOG: "its host stopped answering (watchdog)",
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


class DeviceNotReady(CdprError):
    """The device is in a state the host must not clear on its own (exit status 1)."""


@dataclass(frozen=True)
class DeviceCheck:
    """The status as found at connect (before anything was cleared) and what was done."""

    found: DeviceStatus
    notices: tuple[str, ...]

    @property
    def homed(self) -> bool:
        return self.found.homed_mask & ALL_MODULES == ALL_MODULES


def _fault_name(code: int) -> str:
    try:
        return ErrorCode(code).name.lower()
    except ValueError:
        return f"error {code}"


def describe_fault(st: DeviceStatus) -> str | None:
    """The device's fault in words (None when it is not faulted): what, why, where it stopped."""
    if not st.faulted:
        return None
    code = st.last_error
    why = _WHY.get(ErrorCode(code), "") if code in ErrorCode._value2member_map_ else ""
    text = f"the device is stopped by a fault ({_fault_name(code)}{': ' + why if why else ''})"
    return f"{text} after segment {st.segments_done}"


def fault_clearable(st: DeviceStatus) -> bool:
    """A host may clear it (thermal faults need the heater checked and a power cycle)."""
    return not (st.faulted and st.last_error in THERMAL_ERRORS)


def prepare_device(machine: Machine, *, clear_fault: bool = True) -> DeviceCheck:
    """Read the device's state; stop an earlier session's motion, clear a fault (saying so;
    only when ``clear_fault``: otherwise a fault is refused, the operator decides), or raise
    :class:`DeviceNotReady`."""
    link = machine.link
    found = machine.status()
    notices: list[str] = []
    st = found
    if not fault_clearable(st):
        raise DeviceNotReady(
            f"the device reports {_fault_name(st.last_error).replace('_', ' ')} "
            f"(hotend {st.hotend_c:.0f} C, bed {st.bed_c:.0f} C) from before this connection: "
            "check the heater and its sensor, then power-cycle the device"
        )
    if st.faulted and not clear_fault:
        raise DeviceNotReady(f"{describe_fault(st)}: clear it first (nothing moved)")
    if st.busy and not st.faulted:
        queued = st.items_received - st.items_done
        notices.append(
            f"the device was still executing an earlier session's motion ({queued} items queued; "
            "its host is gone): stopped, heaters and motors kept"
        )
        link.emergency_stop(flags=EstopFlag.KEEP_HEATERS | EstopFlag.KEEP_MOTORS)
        st = machine.status()
    if st.faulted:
        why = (
            _WHY.get(ErrorCode(st.last_error), "")
            if st.last_error in ErrorCode._value2member_map_
            else ""
        )
        if st.last_error and found.faulted:
            notices.append(
                f"the device was stopped by a fault ({_fault_name(st.last_error)}"
                f"{': ' + why if why else ''}) after segment {st.segments_done}: cleared"
            )
        link.clear_fault()
        st = machine.status()
    if st.hotend_target_c > 0 or st.bed_target_c > 0:
        notices.append(
            f"heaters were on from an earlier session (hotend {st.hotend_target_c:g} C, "
            f"bed {st.bed_target_c:g} C)"
        )
    for text in notices:
        log.info("%s: %s", getattr(link, "name", "device"), text)
    return DeviceCheck(found, tuple(notices))
