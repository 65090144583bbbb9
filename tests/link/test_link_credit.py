"""Flow-control credit against a scripted device: reports that acknowledge frames
without carrying flow information must not inflate the credit."""

from __future__ import annotations

import numpy as np

import firmware_protocol.messages as M
from cdprhost.link.host_link import HostLink
from firmware_protocol.framing import Deframer, Kind, encode_frame
from firmware_protocol.message_codec import decode_messages, encode_message
from firmware_protocol.segments import SegmentBatch, SegmentContext


class ScriptedDevice:
    """A transport whose 'device' answers HELLO and otherwise says only what the test queues."""

    name = "scripted"

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.t = 0.0
        self.inbox = bytearray()
        self.written: list = []
        self._deframer = Deframer()
        self.scripted = False  # True: DATA frames get no automatic answer (the test speaks)
        self.seq = 0  # the device's next DATA sequence number
        self.expected = 0  # the host's next DATA sequence number

    def now(self) -> float:
        return self.t

    def write(self, data: bytes) -> None:
        for f in self._deframer.feed(data):
            msgs = decode_messages(f.payload, SegmentContext()) if f.kind != Kind.DATA else None
            if f.kind == Kind.URGENT and isinstance(msgs[0], M.Hello):
                ident = M.Ident(
                    nonce=msgs[0].nonce,
                    major=M.PROTOCOL_MAJOR,
                    minor=0,
                    boot_id=7,
                    firmware_name="scripted",
                    firmware_version="0",
                    axes=4,
                    queue_capacity=self.capacity,
                    clock_hz=100_000,
                    cpu_hz=16_000_000,
                    max_step_rate=100_000,
                    max_payload=248,
                    rx_window=4096,
                    heaters=2,
                    fans=1,
                    hotend_max_dc=2850,
                    bed_max_dc=1200,
                    watchdog_ms=2000,
                    start_ticks=0,
                    items_received=0,
                    items_done=0,
                    segments_received=0,
                    segments_done=0,
                    clock=round(self.t * 100_000),
                )
                self.inbox += encode_frame(Kind.URGENT, 0, 0, encode_message(ident))
            elif f.kind == Kind.DATA and not self.scripted:
                self.expected = (f.seq + 1) % 256
                msgs = decode_messages(f.payload, SegmentContext())
                if any(isinstance(m, M.GetStatus) for m in msgs):
                    status = M.Status(
                        0x40, self.capacity, 0, 0, 0, 0, 0, round(self.t * 100_000),
                        (0, 0, 0, 0), 250, 0, 250, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                    )  # fmt: skip
                    self.inbox += encode_frame(
                        Kind.DATA, self.seq, self.expected, encode_message(status)
                    )
                    self.seq += 1
                # every frame is acknowledged with a flow report (it carries the clock)
                flow = M.Flow(0x40, self.capacity, 0, 0, 0, round(self.t * 100_000))
                self.inbox += encode_frame(Kind.ACK, 0, self.expected, encode_message(flow))
            self.written.append(f)

    def read(self, timeout: float) -> bytes:
        self.t += timeout if not self.inbox else 0.0
        out = bytes(self.inbox)
        self.inbox.clear()
        return out

    def close(self) -> None:
        pass


def segments(n: int) -> SegmentBatch:
    return SegmentBatch(np.full(n, 1000), np.ones((n, 4), dtype=np.int64), np.full(n, -1))


def queued_items(frames) -> list[int]:
    counts = [
        sum(1 for m in decode_messages(f.payload, SegmentContext()) if m.QUEUED)
        for f in frames
        if f.kind == Kind.DATA
    ]
    return [c for c in counts if c]


def test_a_report_acknowledging_frames_does_not_grant_credit():
    dev = ScriptedDevice(capacity=10)
    link = HostLink(dev, timeout_s=5.0, baud=None)
    link.handshake()  # status requests and CONFIGURE, answered by the script
    dev.scripted = True
    frame = dev.expected  # the sequence number the segments' frame gets
    link.queue_segments(segments(7))  # credit 10: one frame of 7
    assert queued_items(dev.written) == [7]
    # the device accepts it and, before its flow report, sends an event that acknowledges it
    after = frame + 1
    dev.inbox += encode_frame(Kind.DATA, dev.seq, after, encode_message(M.Event(2, 0, (0, 2000))))
    dev.t += 0.001
    link.poll()
    assert link._core.credit() == 3  # 10 free before the frame, minus its 7 items
    dev.inbox += encode_frame(Kind.ACK, 0, after, encode_message(M.Flow(0x11, 3, 0, 0)))
    link.poll()
    assert link._core.credit() == 3
    # six executed
    dev.inbox += encode_frame(Kind.ACK, 0, after, encode_message(M.Flow(0x11, 9, 6, 6)))
    link.poll()
    assert link._core.credit() == 9
