"""What the host knows about the device: identity, progress, flow, clock, status, events,
failure.

Fed with the endpoint's incoming items (device reports, flow, urgent frames); it
never does I/O. HostLink owns one and raises ``tracker.failure`` when set.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import replace

from cdprhost.link.clock_sync import ClockSync
from cdprhost.link.errors import DeviceFault, DeviceReset, LinkError
from cdprhost.link.events import (
    DeviceCaps,
    DeviceErrorEvent,
    DeviceHealth,
    DeviceProgress,
    DeviceStatus,
    Identity,
    LinkEvent,
    device_event,
    error_text,
)
from cdprhost.link.flow import FlowReport
from cdprhost.link.ring_room import RingReport
from firmware_protocol.block_ring import valid_entries
from firmware_protocol.codes import BootCause
from firmware_protocol.endpoint import Incoming
from firmware_protocol.message_codec import decode_messages
from firmware_protocol.messages import (
    Boot,
    Caps,
    EstopAck,
    Event,
    EventCode,
    Flag,
    Flow,
    Health,
    Ident,
    Message,
    MessageError,
    Ring,
    Status,
    StepBudget,
    Stepping,
)
from firmware_protocol.messages import Error as ErrorReport
from firmware_protocol.segments import SegmentContext

log = logging.getLogger(__name__)


def decode_one(payload: bytes) -> Message | None:
    """The single message of an URGENT payload (None if it does not parse)."""
    try:
        msgs = decode_messages(payload, SegmentContext())
    except MessageError:
        return None
    return msgs[0] if len(msgs) == 1 else None


class DeviceTracker:
    def __init__(self, name: str):
        self.name = name
        self.identity: Identity | None = None
        self.progress = DeviceProgress(0, 0, 0, 0)
        self.flow = FlowReport()
        self.ring: RingReport | None = None  # the latest RING (3.2; None: no ring)
        self.clock = ClockSync(100_000)
        self.flows = 0  # FLOW reports received (the streaming loop wakes on them)
        self.status: DeviceStatus | None = None
        self.status_count = 0
        self.events: deque[LinkEvent] = deque(maxlen=4096)
        self.progress_dirty = False
        self.failure: LinkError | None = None
        self.estop_acked = False
        self.cleared = False
        self.clearing = False  # errors reported before CLEAR_FAULT reached the device are stale
        self.refused: int = 0  # the latched fault of a CLEAR_FAULT the device refused
        self.caps: DeviceCaps | None = None
        self.health: DeviceHealth | None = None
        self.tuned: dict[int, tuple[int, ...]] = {}  # heater -> gains of its last AUTOTUNE

    def accept_ident(self, msg: Ident, now: float) -> None:
        self.identity = Identity.from_message(msg)
        free = msg.queue_capacity - (msg.items_received - msg.items_done)
        self.flow = FlowReport(free=free, ack=0, t=now)
        self.ring = None
        self.progress = DeviceProgress(msg.items_done, msg.segments_done, free, 0)
        self.clock = ClockSync(msg.clock_hz)
        self.clock.add(now, msg.clock)
        self.failure = None

    def set_progress(self, items: int, segments: int, free: int, flags: int) -> None:
        p = DeviceProgress(
            max(items, self.progress.items_done),
            max(segments, self.progress.segments_done),
            free,
            flags,
        )
        if p != self.progress:
            if (p.flags ^ self.progress.flags) & (Flag.FAULT | Flag.ESTOP | Flag.MOVING):
                log.debug("%s: device flags %s", self.name, Flag(p.flags))
            self.progress = p
            self.progress_dirty = True

    def forget_errors(self) -> None:
        """The fault was cleared: its error reports not taken yet are history, not news (a
        job started after the clear would take them for a fault of its own)."""
        kept = [e for e in self.events if not isinstance(e, DeviceErrorEvent)]
        self.events.clear()
        self.events.extend(kept)

    def take_events(self) -> list[LinkEvent]:
        out = list(self.events)
        self.events.clear()
        if self.progress_dirty:
            self.progress_dirty = False
            out.append(self.progress)
        return out

    def handle(self, inc: Incoming, now: float) -> None:
        if inc.kind == "urgent":
            msg = decode_one(inc.payload)
            if isinstance(msg, Boot):
                self._on_boot(msg)
            elif isinstance(msg, EstopAck):
                self.estop_acked = True
                self.set_progress(
                    msg.items_done,
                    msg.segments_done,
                    self.progress.queue_free,
                    self.progress.flags | Flag.ESTOP | Flag.FAULT,
                )
            return
        try:
            msgs = decode_messages(inc.payload, SegmentContext())
        except MessageError:
            log.warning("%s: a device report that does not parse was ignored", self.name)
            return
        for msg in msgs:
            if isinstance(msg, Flow):
                # its motion counted from when it was sent (a report read late is not fresh)
                sent = self.clock.add(now, msg.clock)
                self.flow = FlowReport(msg.queue_free, inc.ack, msg.buffered_ticks, msg.flags, sent)
                self.flows += 1
                self.set_progress(msg.items_done, msg.segments_done, msg.queue_free, msg.flags)
            elif isinstance(msg, Ring):  # follows FLOW (3.2)
                if valid_entries(msg.entries):
                    self.ring = RingReport(msg.entries, msg.head, msg.tail, msg.held, inc.ack)
                else:
                    log.warning(
                        "%s: a RING of %d entries (not a power of two) was ignored",
                        self.name,
                        msg.entries,
                    )
            elif isinstance(msg, Status):
                # no clock sample: a status may be a retransmission (an old clock, late)
                self.status = DeviceStatus.from_message(msg, self.identity, now)
                self.status_count += 1
            elif isinstance(msg, Health):  # follows its STATUS in the same payload
                self.health = DeviceHealth.from_message(msg)
                if self.status is not None:
                    self.status = replace(self.status, health=self.health)
            elif isinstance(msg, Caps):
                self.caps = DeviceCaps.from_message(msg)
            elif isinstance(msg, Stepping):  # follows its CAPS (3.1)
                self.caps = replace(
                    self.caps or DeviceCaps(), profile_step_rate=msg.profile_step_rate
                )
            elif isinstance(msg, StepBudget):  # follows its STEPPING (3.3)
                self.caps = replace(self.caps or DeviceCaps(), total_step_rate=msg.total_step_rate)
            elif isinstance(msg, ErrorReport):
                self.events.append(device_event(msg))
                if not self.clearing:
                    log.warning("%s: device error %s", self.name, error_text(msg))
                    self.failure = DeviceFault(
                        f"{self.name}: device error {error_text(msg)}",
                        code=msg.code,
                        item=msg.item,
                        segment=msg.segment,
                        axis=msg.axis,
                        value=msg.value,
                    )
            elif isinstance(msg, Event):
                self.events.append(device_event(msg))
                if msg.code == EventCode.FAULT_CLEARED:
                    log.info("%s: device fault cleared", self.name)
                    self.cleared = True
                    self.clearing = False
                    p = self.progress  # the device said so: its flags until the next report
                    self.set_progress(
                        p.items_done,
                        p.segments_done,
                        p.queue_free,
                        p.flags & ~(Flag.FAULT | Flag.ESTOP),
                    )
                elif msg.code == EventCode.CLEAR_REFUSED and msg.values:
                    self.refused = msg.values[0]
                elif msg.code == EventCode.AUTOTUNE_DONE and len(msg.values) == 4:
                    self.tuned[msg.values[0]] = tuple(msg.values[1:])
            elif isinstance(msg, Ident):
                self.identity = Identity.from_message(msg)

    def _on_boot(self, msg: Boot) -> None:
        if self.identity is None or msg.boot_id == self.identity.boot_id:
            return
        exact = bool(msg.prev_valid)
        seg = msg.prev_segments_done if exact else self.progress.segments_done
        item = msg.prev_items_done if exact else self.progress.items_done
        self.set_progress(item, seg, 0, Flag.FAULT)
        cause = boot_cause_text(msg.cause)
        log.warning("%s: device reset (%s, boot id %#010x)", self.name, cause, msg.boot_id)
        self.failure = DeviceReset(
            f"{self.name}: the device reset ({cause}; boot id {self.identity.boot_id:#010x} -> {msg.boot_id:#010x}); "
            f"last executed segment {seg}{'' if exact else ' (last reported; the device kept no record)'}",
            last_segment=seg,
            last_item=item,
            exact=exact,
        )


def boot_cause_text(cause: int) -> str:
    """BOOT's cause in words (a DTR auto-reset at connect is an external reset)."""
    try:
        name = BootCause(cause).name
    except ValueError:
        return f"cause {cause}"
    return {
        "EXTERNAL_RESET": "external reset: the RESET pin, e.g. the DTR auto-reset of opening the port",
    }.get(name, name.lower().replace("_", "-"))
