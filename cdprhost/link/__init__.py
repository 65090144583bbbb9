"""The serial link to the printer's firmware (protocol: firmware_protocol/PROTOCOL.md).

Getting a link (a handshaken :class:`HostLink`; the embedded simulated device is
:func:`cdprhost.sim.embedded.open_embedded`, with the same interface)::

    open_link(port, baud=250000, timeout_s=2.0) -> HostLink
        port: a device path or any pyserial URL (loop://, socket://host:port, ...);
        opened exclusively.

HostLink (thread-safe; every call pumps the link; nothing runs in the background)::

    link.identity            Identity: protocol, firmware_name/version, axes, queue_capacity,
                             clock_hz (unit of segment/dwell ticks), max_step_rate, boot_id, ...
    link.queue_segments(SegmentBatch(ticks, deltas, ramps), timeout=None) -> range
                             segment numbers as in the device record; blocks while the
                             device queue or the window is full
    link.send(*commands, timeout=None) -> list[int]
                             firmware_protocol.messages commands: SetHeater, WaitHeater, SetFan,
                             Dwell, Home, SetPosition, Enable (queued, returns their item numbers)
                             and GetStatus, ClearFault (immediate, 0)
    link.progress            Progress(items_done, segments_done, queue_free, flags) (no I/O)
    link.status()            latest DeviceStatus (no I/O); link.request_status(timeout) asks
    link.poll(timeout=0.0)   pump, then return events: Progress (latest, if changed),
                             DeviceEvent, DeviceErrorEvent (call it every ~0.1 s when idle)
    link.wait_idle(timeout)  all queued items executed and motion stopped
    link.wait_items(n, timeout)
    link.emergency_stop(timeout=1.0) -> bool   bypasses the queue and the window
    link.clear_fault()       leave the device's fault state (after DeviceFault / e-stop)
    link.counters            LinkCounters(retransmits, timeouts, naks_received, naks_sent,
                             bad_frames, frames_sent, frames_received, bytes_sent, ...)
    link.handshake()         a new session (e.g. after DeviceReset); numbering continues
                             from the device's counters
    link.items_sent, link.segments_sent, link.now(), link.close()

Segments (firmware_protocol.segments): ``ticks`` durations in device ticks
(``identity.clock_hz``), ``deltas`` (N, 4) signed steps for modules 1..3 and the
extruder, ``ramps`` codes from ``ramp_codes_from_speeds(v_start, v_end)`` (-1 =
constant speed; 255 = ends at rest, which the last segment of every motion block
must do, or the device reports a queue underrun).

Errors (all LinkError(CdprError), exit 1 unless noted): PortNotFound (exit 2),
PortBusy, PortVanished, DeviceSilent, ProtocolMismatch, DeviceReset(last_segment,
last_item, exact), DeviceFault(code, item, segment, axis, value), LinkTimeout.
"""

from cdprhost.link.connect import open_link
from cdprhost.link.errors import (
    DeviceFault,
    DeviceReset,
    DeviceSilent,
    LinkError,
    LinkTimeout,
    PortBusy,
    PortNotFound,
    PortVanished,
    ProtocolMismatch,
)
from cdprhost.link.events import (
    DeviceErrorEvent,
    DeviceEvent,
    DeviceStatus,
    Identity,
    LinkCounters,
    Progress,
)
from cdprhost.link.host_link import HostLink

__all__ = [
    "DeviceErrorEvent",
    "DeviceEvent",
    "DeviceFault",
    "DeviceReset",
    "DeviceSilent",
    "DeviceStatus",
    "HostLink",
    "Identity",
    "LinkCounters",
    "LinkError",
    "LinkTimeout",
    "PortBusy",
    "PortNotFound",
    "PortVanished",
    "Progress",
    "ProtocolMismatch",
    "open_link",
]
