"""The serial link to the printer's firmware (protocol: firmware_protocol/PROTOCOL.md).

Getting a link (a handshaken :class:`HostLink`; the embedded simulated device is
:func:`cdprhost.sim.embedded.open_embedded`, with the same interface)::

    open_link(port, baud=250000, timeout_s=2.0) -> HostLink
        port: a device path or any pyserial URL (loop://, socket://host:port, ...);
        opened exclusively.

HostLink (thread-safe; every call pumps the link; on a real port a keep-alive thread
holds the session while nobody calls)::

    link.identity            Identity: protocol, firmware_name/version, axes, queue_capacity,
                             clock_hz (unit of segment/dwell ticks), max_step_rate, rx_window,
                             heaters, fans, hotend_max_c, bed_max_c, watchdog_ms, boot_id, ...
    link.feed(batch, start=0, max_wait=0.0) -> int
                             stream segments of a SegmentBatch(ticks, deltas, ramps) from
                             ``start`` as far as the device's slots and the time watermarks
                             allow, waiting for room (woken by flow reports) at most max_wait s;
                             returns the index after the last one sent
    link.queue_segments(batch, timeout=None) -> range
                             the same, blocking until all are sent; their segment numbers
    link.flush()             FLUSH: what was sent may start now (end of a stream, a pause)
    link.send(*commands, timeout=None) -> list[int]
                             firmware_protocol.messages commands: SetHeater, WaitHeater, SetFan,
                             Dwell, Home, SetPosition, Enable (queued, returns their item numbers)
                             and GetStatus, ClearFault, Flush, Configure (immediate, 0)
    link.progress            DeviceProgress(items_done, segments_done, queue_free, flags) (no I/O)
    link.status()            latest DeviceStatus (no I/O); link.request_status(timeout) asks
    link.poll(timeout=0.0)   pump, then return events: DeviceProgress (latest, if changed),
                             DeviceEvent, DeviceErrorEvent
    link.wait_report(timeout)  pump until the next report (flow, status, error)
    link.wait_idle(timeout)  FLUSH, then wait until all queued items executed and motion stopped
    link.wait_items(n, timeout)
    link.emergency_stop(timeout=1.0, flags=0) -> bool   bypasses the queue and the window
    link.clear_fault()       leave the device's fault state (after DeviceFault / e-stop); a
                             latched thermal fault is refused: DeviceFault naming it
    link.counters            LinkCounters(retransmits, timeouts, naks_received, naks_sent,
                             bad_frames, frames_sent, frames_received, bytes_sent, ...,
                             late_pulses, late_worst_us, rx_overruns: the device's HEALTH;
                             host_late_worst_s, lead_low_max_s: the host's own lateness to
                             a refill and the highest low watermark it kept, flow.py)
    link.set_machine(DeviceSetup)  travel limits and PID gains, sent at every connect
                             (Machine does it from the profile: device_setup.setup_from_profile)
    link.caps, link.health   a 2.1 device's CAPS and latest HEALTH (None from a 2.0 device)
    link.tuned_gains         heater -> (kp, ki, kd) x1000 of its last AUTOTUNE
    link.start_keepalive()   a thread that keeps the session (never the heater lease: the
                             calls above renew it, so a wedged caller loses its heaters)
    link.clock_rate          device ticks per host second (measured)
    link.handshake()         a new session (e.g. after DeviceReset); numbering continues
                             from the device's counters
    link.items_sent, link.segments_sent, link.now(), link.close()

A stream's caller (the job; queue_segments does it itself) runs it inside
``quiet_collection()``: the garbage collector then scans only what the stream made lately,
so it never pauses the feed longer than a device fed short segments holds (collector.py).

Segments (firmware_protocol.segments): ``ticks`` durations in device ticks
(``identity.clock_hz``), ``deltas`` (N, 4) signed steps for modules 1..3 and the
extruder, ``ramps`` codes from ``ramp_codes_from_speeds(v_start, v_end)`` (-1 =
constant speed; 255 = ends at rest, which the last segment of every motion block
must do, or the device reports a queue underrun). A segment over the device's step
rate raises StepRateError (a ValueError) before anything is sent.

Errors (all LinkError(CdprError), exit 1 unless noted): PortNotFound (exit 2),
PortBusy, PortVanished, DeviceSilent, ProtocolMismatch, DeviceReset(last_segment,
last_item, exact), DeviceFault(code, item, segment, axis, value), LinkTimeout.
"""

from cdprhost.link.collector import quiet_collection
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
    StepRateError,
)
from cdprhost.link.events import (
    DeviceErrorEvent,
    DeviceEvent,
    DeviceProgress,
    DeviceStatus,
    Identity,
    LinkCounters,
)
from cdprhost.link.flow import Watermarks
from cdprhost.link.host_link import HostLink

__all__ = [
    "DeviceErrorEvent",
    "DeviceEvent",
    "DeviceFault",
    "DeviceProgress",
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
    "ProtocolMismatch",
    "StepRateError",
    "Watermarks",
    "open_link",
    "quiet_collection",
]
