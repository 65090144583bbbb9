"""Flow-control credit against a scripted device: reports that acknowledge frames
without carrying flow information must not inflate the credit."""

from __future__ import annotations

import numpy as np

import firmware_protocol.messages as M
from cdprhost.link.host_link import HostLink
from firmware_protocol.framing import Deframer, Kind, encode_frame
from firmware_protocol.messages import decode_messages, encode_message
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

    def now(self) -> float:
        return self.t

    def write(self, data: bytes) -> None:
        for f in self._deframer.feed(data):
            msgs = decode_messages(f.payload, SegmentContext()) if f.kind != Kind.DATA else None
            if f.kind == Kind.URGENT and isinstance(msgs[0], M.Hello):
                ident = M.Ident(
                    msgs[0].nonce,
                    1,
                    0,
                    7,
                    "scripted",
                    "0",
                    4,
                    self.capacity,
                    100_000,
                    100_000,
                    248,
                    2,
                    1,
                    0,
                    0,
                    0,
                    0,
                )
                self.inbox += encode_frame(Kind.URGENT, 0, 0, encode_message(ident))
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
    return [
        sum(1 for m in decode_messages(f.payload, SegmentContext()) if m.QUEUED)
        for f in frames
        if f.kind == Kind.DATA
    ]


def test_a_report_acknowledging_frames_does_not_grant_credit():
    dev = ScriptedDevice(capacity=10)
    link = HostLink(dev, timeout_s=5.0, baud=None)
    link.handshake()
    link.queue_segments(segments(7))  # credit 10: one frame of 7
    assert queued_items(dev.written) == [7]
    # the device accepts it and, before its flow report, sends an event that acknowledges frame 0
    dev.inbox += encode_frame(Kind.DATA, 0, 1, encode_message(M.Event(2, 0, (0, 2000))))
    dev.t += 0.001
    link.poll()
    assert link._credit() == 3  # 10 free before frame 0, minus its 7 items
    dev.inbox += encode_frame(Kind.ACK, 0, 1, encode_message(M.Flow(0x11, 3, 0, 0)))
    link.poll()
    assert link._credit() == 3
    dev.inbox += encode_frame(Kind.ACK, 0, 1, encode_message(M.Flow(0x11, 9, 6, 6)))  # six executed
    link.poll()
    assert link._credit() == 9
