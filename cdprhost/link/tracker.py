"""What the host knows about the device: identity, progress, status, events, failure.

Fed with the endpoint's incoming items (device reports, flow, urgent frames); it
never does I/O. HostLink owns one and raises ``tracker.failure`` when set.
"""

from __future__ import annotations

from collections import deque

from cdprhost.link.errors import DeviceFault, DeviceReset, LinkError
from cdprhost.link.events import (
    DeviceStatus,
    Identity,
    LinkEvent,
    Progress,
    device_event,
    error_text,
)
from firmware_protocol.endpoint import Incoming
from firmware_protocol.messages import (
    Boot,
    EstopAck,
    Event,
    EventCode,
    Flag,
    Flow,
    Ident,
    Message,
    MessageError,
    Status,
    decode_messages,
)
from firmware_protocol.messages import Error as ErrorReport
from firmware_protocol.segments import SegmentContext


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
        self.progress = Progress(0, 0, 0, 0)
        self.flow_free = 0
        self.flow_ack = 0  # flow_free counts every frame before this sequence number
        self.status: DeviceStatus | None = None
        self.status_count = 0
        self.events: deque[LinkEvent] = deque(maxlen=4096)
        self.progress_dirty = False
        self.failure: LinkError | None = None
        self.estop_acked = False
        self.cleared = False
        self.clearing = False  # errors reported before CLEAR_FAULT reached the device are stale

    def accept_ident(self, msg: Ident, max_payload: int) -> None:
        self.identity = Identity.from_message(msg)
        self.flow_free = msg.queue_capacity - (msg.items_received - msg.items_done)
        self.flow_ack = 0
        self.progress = Progress(msg.items_done, msg.segments_done, self.flow_free, 0)
        self.failure = None

    def set_progress(self, items: int, segments: int, free: int, flags: int) -> None:
        p = Progress(
            max(items, self.progress.items_done),
            max(segments, self.progress.segments_done),
            free,
            flags,
        )
        if p != self.progress:
            self.progress = p
            self.progress_dirty = True

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
            return
        for msg in msgs:
            if isinstance(msg, Flow):
                self.flow_free = msg.queue_free
                self.flow_ack = inc.ack
                self.set_progress(msg.items_done, msg.segments_done, msg.queue_free, msg.flags)
            elif isinstance(msg, Status):
                self.status = DeviceStatus.from_message(msg, self.identity, now)
                self.status_count += 1
            elif isinstance(msg, ErrorReport):
                self.events.append(device_event(msg))
                if not self.clearing:
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
                    self.cleared = True
                    self.clearing = False
            elif isinstance(msg, Ident):
                self.identity = Identity.from_message(msg)

    def _on_boot(self, msg: Boot) -> None:
        if self.identity is None or msg.boot_id == self.identity.boot_id:
            return
        exact = bool(msg.prev_valid)
        seg = msg.prev_segments_done if exact else self.progress.segments_done
        item = msg.prev_items_done if exact else self.progress.items_done
        self.set_progress(item, seg, 0, Flag.FAULT)
        self.failure = DeviceReset(
            f"{self.name}: the device reset (boot id {self.identity.boot_id:#010x} -> {msg.boot_id:#010x}); "
            f"last executed segment {seg}{'' if exact else ' (last reported; the device kept no record)'}",
            last_segment=seg,
            last_item=item,
            exact=exact,
        )
