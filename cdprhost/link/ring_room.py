"""The device's ring of schedule-block entries as the host follows it (protocol 3.2:
``RING``; the placement rule is :mod:`firmware_protocol.block_ring`).

The host sends a segment with a schedule block only when the device's rule places the
block without a wait, by the tail of the latest ``RING``: a block that does not fit waits
on the host with its frame, instead of in the device's deframer, where the frames behind
it were refused and sent again (the step engine at 26,000 steps/s on the cup's upper
layers: docs/step-engine.md section 8). Pure bookkeeping, no I/O.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

from firmware_protocol.block_ring import COUNTER, admit

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RingReport:
    """The latest ``RING``, in the report that acknowledged the frames before ``ack``;
    ``held``: items of those the device had not queued yet (their blocks not placed)."""

    entries: int
    head: int
    tail: int
    held: int
    ack: int


class RingRoom:
    """Where the device's next block goes: the head the host projects over the blocks it
    sent, taken from a report whenever it counts every block sent: nothing in flight
    after its ``ack`` and nothing ``held`` (a session's first report, every pause of
    the stream; between those the projection is exact, the rule being the device's)."""

    def __init__(self) -> None:
        self.head: int | None = None  # None: not known yet (no report counted every frame)
        self.disagreements = 0  # a projected head the device's report contradicted
        self.held = 0  # turns a block waited on the host for room
        self.mean_need = 0.0  # entries of the blocks sent, a running mean

    def follow(self, report: RingReport | None, in_flight_items: int) -> None:
        """Take up the latest report; ``in_flight_items``: queue items in the frames from
        its ``ack`` on."""
        if report is None:
            self.head = None
            return
        if in_flight_items or report.held:
            return
        if self.head is not None and self.head != report.head:
            self.disagreements += 1
            log.warning(
                "the device's ring of blocks has its head at %d where the host counted %d",
                report.head,
                self.head,
            )
        self.head = report.head

    def admit(self, report: RingReport | None, needs: Sequence[int]) -> int:
        """How many of the segments ``needs`` (each block's entries, 0 for a segment
        without one) may go now; the head moves past the blocks of those."""
        if report is None:
            return len(needs)
        if self.head is None:  # only the segments before the first block
            return next((i for i, need in enumerate(needs) if need), len(needs))
        n, head = admit(self.head, report.tail, needs, report.entries)
        if n < len(needs):
            self.held += 1
        self.head = head
        for need in needs[:n]:
            if need:
                self.mean_need += (need - self.mean_need) / 8 if self.mean_need else need
        return n

    def blocks_room(self, report: RingReport | None) -> int | None:
        """About how many more blocks the ring takes now (None: no limit known): the
        feed fits no more ramps in a turn than that (a ramp's fit takes milliseconds in
        Python, and the ring holds a few tens of ms of fast ramps)."""
        if report is None or self.head is None or not self.mean_need:
            return None
        free = report.entries - (self.head - report.tail) % COUNTER
        return max(1, int(free / self.mean_need) + 1)
