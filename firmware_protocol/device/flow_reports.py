"""When the simulated firmware sends an unsolicited FLOW (PROTOCOL.md section 6), and
what it carries: every ``flow_ticks`` of executed motion, at once when the flags change,
when an eighth of the queue was freed, and any other change after ``interval_s``."""

from __future__ import annotations

import math
from itertools import islice

from firmware_protocol.device import queue_items as m
from firmware_protocol.device.machine import DeviceMachine
from firmware_protocol.message_codec import encode_message
from firmware_protocol.messages import Flow


def executed_ticks(mc: DeviceMachine, T: float) -> int:
    """Motion executed so far, the running segment's elapsed part included."""
    cur = mc.current
    extra = 0
    if cur is not None and cur.kind in m.TIMED and mc.cur_end > mc.cur_start:
        extra = int((min(T, mc.cur_end) - mc.cur_start) * mc.clock_hz)
    return mc.motion_ticks + max(0, extra)


class FlowReports:
    """The state of one session's flow reports (what the last one said, and when)."""

    def __init__(self, flow_ticks: int, interval_s: float, step: int):
        self.flow_ticks = flow_ticks
        self.interval_s = interval_s
        self.step = max(1, step)
        self.sent: tuple[int, int] | None = None  # (items_done, flags) of the last one
        self.free_sent = 0
        self.motion_sent = 0
        self.time = -math.inf
        self._freed_key: tuple[int, int, int, float] | None = None
        self._freed: float | None = None

    def wanted(self, mc: DeviceMachine, now: float, T: float) -> bool:
        sent = self.sent
        if sent is None:
            return True
        if self.flow_ticks > 0 and executed_ticks(mc, T) - self.motion_sent >= self.flow_ticks:
            return True
        state = (mc.items_done, mc.flags())
        if state == sent:
            return False
        return (
            state[1] != sent[1]
            or mc.free_slots() >= self.free_sent + self.step
            or now >= self.time + self.interval_s
        )

    def due(self, mc: DeviceMachine, now: float, speedup: float) -> float | None:
        """When the next unsolicited FLOW falls due if nothing arrives (None: never)."""
        if self.sent is None:
            return now
        due = math.inf
        if (mc.items_done, mc.flags()) != self.sent:
            due = self.time + self.interval_s
        cur = mc.current
        if cur is not None and cur.kind in m.TIMED:
            if self.flow_ticks > 0:
                # when the executed motion reaches the threshold if it runs on without a gap
                # (an absolute time: the machine may not have been advanced to ``now`` yet)
                need = self.motion_sent + self.flow_ticks - mc.motion_ticks + 1
                due = min(due, (mc.cur_start + need / mc.clock_hz) / speedup)
            key = (mc.items_done, len(mc.queue), self.free_sent, mc.cur_end)
            freed = self._freed if key == self._freed_key else self._freed_at(mc, key)
            if freed is not None:
                due = min(due, freed / speedup)
        return None if due == math.inf else max(now, due)

    def _freed_at(self, mc: DeviceMachine, key: tuple[int, int, int, float]) -> float | None:
        """Machine time at which an eighth of the queue will have been freed since the last
        report, the items ahead running back to back (None: not foreseeable, or not before
        a homing or a wait, whose lengths are known only once they run). Without it a queue
        of short segments ran dry before the report that would have refilled it: the
        firmware notices the freed slots as they come, the model only at a deadline. Kept
        for its ``key``: the items done, queued and free at the last report, the current
        one's end (a TIMED one)."""
        more = self.free_sent + self.step - mc.free_slots()  # items still to end
        ahead = list(islice(mc.queue, max(0, more - 1)))
        freed = None
        if (
            more >= 1
            and mc.cur_end != math.inf
            and all(it.kind in (m.SEG, m.DWELL) for it in ahead)
        ):
            freed = mc.cur_end + sum(it.ticks for it in ahead) / mc.clock_hz
        self._freed_key, self._freed = key, freed
        return freed

    def payload(self, mc: DeviceMachine, now: float, T: float) -> bytes:
        flags = mc.flags()
        self.sent = (mc.items_done, flags)
        self.free_sent = mc.free_slots()
        self.motion_sent = executed_ticks(mc, T)
        self.time = now
        return encode_message(
            Flow(
                flags,
                max(0, mc.free_slots()),
                mc.items_done,
                mc.segments_done,
                mc.buffered_ticks(T),
                mc.clock(T),
            )
        )
