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
from cdprhost.machine.faults import (
    CLEAR_HINT,
    describe_fault,
    fault_clearable,
    fault_name,
    fault_why,
)
from cdprhost.machine.operations import ALL_MODULES, Machine
from firmware_protocol.messages import BED, HOTEND, EstopFlag

__all__ = ["DeviceCheck", "DeviceNotReady", "describe_fault", "fault_clearable", "prepare_device"]

log = logging.getLogger(__name__)


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
            f"the device reports {fault_name(st.last_error).replace('_', ' ')} "
            f"(hotend {st.hotend_c:.0f} C, bed {st.bed_c:.0f} C) from before this connection: "
            "check the heater and its sensor, then power-cycle the device"
        )
    if st.faulted and not clear_fault:
        raise DeviceNotReady(f"{describe_fault(st)}: clear it first (nothing moved); {CLEAR_HINT}")
    if st.busy and not st.faulted:
        queued = st.items_received - st.items_done
        notices.append(
            f"the device was still executing an earlier session's motion ({queued} items queued; "
            "its host is gone): stopped, heaters and motors kept"
        )
        link.emergency_stop(flags=EstopFlag.KEEP_HEATERS | EstopFlag.KEEP_MOTORS)
        st = machine.status()
    if st.faulted:
        why = fault_why(st.last_error)
        if st.last_error and found.faulted:
            notices.append(
                f"the device was stopped by a fault ({fault_name(st.last_error)}"
                f"{': ' + why if why else ''}) after segment {st.segments_done}: cleared"
            )
        link.clear_fault()
        st = machine.status()
    mine = getattr(link, "heaters_set", {})  # set by this host since it connected: not earlier
    earlier = [
        t > 0 and heater not in mine
        for heater, t in ((HOTEND, st.hotend_target_c), (BED, st.bed_target_c))
    ]
    if any(earlier):
        notices.append(
            f"heaters were on from an earlier session (hotend {st.hotend_target_c:g} C, "
            f"bed {st.bed_target_c:g} C)"
        )
    for text in notices:
        log.info("%s: %s", getattr(link, "name", "device"), text)
    return DeviceCheck(found, tuple(notices))
