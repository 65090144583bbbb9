"""The simulated device's ring of schedule-block entries, as the AVR's step engine keeps
one (protocol 3.2: ``RING``; ``DeviceConfig.ring_entries``, none by default: this model
steps every axis exactly and needs no room for blocks).

Each segment's block takes its entries by the device's placement rule
(:mod:`firmware_protocol.block_ring`) as the segment is queued, and frees them at the
segment's end. A frame whose blocks would wait for room is refused, as a frame over the
queue's free slots is: only a guard, counted in ``rejects`` (a 3.2 host never sends one).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

from firmware_protocol.block_ring import COUNTER, admit, block_entries, most_entries, place
from firmware_protocol.message_base import Message
from firmware_protocol.messages import Ring, Segment


class BlockStore:
    def __init__(self, entries: int, max_payload: int):
        self.entries = entries
        self.most = most_entries(max_payload)
        self.head = self.tail = 0
        self.ends: deque[tuple[int, int]] = deque()  # (segment, counter after its block)
        self.rejects = 0
        self.sent: tuple[int, bool] | None = None  # the session's last RING: tail, short

    def new_session(self) -> None:
        self.sent = None

    def free_through(self, segments_done: int, idle: bool) -> None:
        """Free the blocks of the segments done (all of them once the machine is idle: a
        flushed queue's blocks too)."""
        while self.ends and self.ends[0][0] <= segments_done:
            self.tail = self.ends.popleft()[1]
        if idle:
            self.ends.clear()
            self.tail = self.head

    def takes(self, needs: list[int]) -> bool:
        """Whether every block of ``needs`` (entries each, in order) goes without a wait."""
        return admit(self.head, self.tail, needs, self.entries)[0] == len(needs)

    def put(self, segment: int, need: int) -> None:
        """Place the block of ``segment`` (checked by :meth:`takes`)."""
        at = place(self.head, self.tail, need, self.entries)
        if at is None:
            raise RuntimeError(f"segment {segment}: its block of {need} entries has no room")
        self.head = (at + need) % COUNTER
        self.ends.append((segment, self.head))

    def short(self) -> bool:
        """A block of the most a frame carries would wait: the host may be holding one."""
        return place(self.head, self.tail, self.most, self.entries) is None

    def report(self) -> Ring:
        """RING for an ACK or NAK (every frame is queued as it arrives: ``held`` 0)."""
        self.sent = (self.tail, self.short())
        return Ring(self.entries, self.head, self.tail, 0)

    @property
    def may_hold_host(self) -> bool:
        """The last RING said a block of the most would wait."""
        return self.sent is not None and self.sent[1]

    def wants_report(self) -> bool:
        """A ring that may hold the host back reports each room the steppers free."""
        return self.sent is not None and self.sent[1] and self.tail != self.sent[0]


def block_needs(msgs: Sequence[Message]) -> list[int]:
    """Entries of the ring each segment's block takes, in order (segments with one)."""
    return [
        block_entries(len(sched.chunks) for _, sched in msg.schedules)
        for msg in msgs
        if isinstance(msg, Segment) and msg.schedules
    ]
