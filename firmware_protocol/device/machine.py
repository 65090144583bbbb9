"""The firmware's machine model: move queue, start rule, step positions, timing, endstops,
heaters.

Driven by device time ``T`` (seconds). Items are executed strictly in order;
segments, dwells and homing take time, the other items are instantaneous. The
motion clock (``motion_ticks``) only advances with executed durations, so the
record is the same whatever the link did. Reports (errors, events) are returned
as protocol messages for the protocol layer to send.

The queue is what a microcontroller keeps: a bounded FIFO of plain tuples, with
two running sums that make the start rule O(1) (PROTOCOL.md section 5.4): the
ticks of the queued segments and dwells, and the number of queued items that end
a block. A start from rest is dated at the moment its condition became true (the
arrival of the data, or the end of the previous item), never earlier.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Protocol

from firmware_protocol.device.config import SimConfig
from firmware_protocol.device.heaters import Heater, heater_outcomes
from firmware_protocol.device.queue_items import (
    DWELL,
    ENABLE,
    FAN,
    HEATER,
    HOLDING,
    HOME,
    SEG,
    SETPOS,
    TIMED,
    TUNE,
    U32,
    WAIT,
    Item,
    _ends_block,
)
from firmware_protocol.device.record import SegmentRecord
from firmware_protocol.device.travel import SoftLimits, segment_refusal, switch_crossing
from firmware_protocol.messages import (
    HEATERS_OFF,
    HOTEND,
    THERMAL_ERRORS,
    Error,
    ErrorCode,
    Event,
    EventCode,
    Flag,
    Message,
)
from firmware_protocol.ramp_profile import RAMP_TO_REST, steps_done
from firmware_protocol.segments import MAX_DELTA

_MOVING, _FAULT, _ESTOP, _HOMED, _ENABLED, _HEATING, _WAITING = (
    int(f)
    for f in (
        Flag.MOVING,
        Flag.FAULT,
        Flag.ESTOP,
        Flag.HOMED,
        Flag.ENABLED,
        Flag.HEATING,
        Flag.WAITING,
    )
)


class Observer(Protocol):
    """Told when motion has come to rest and settled (the virtual mocap takes a picture)."""

    def on_settled(self, steps: tuple[int, ...], t: float, /) -> object: ...


class DeviceMachine:
    def __init__(
        self,
        cfg: SimConfig,
        record: SegmentRecord,
        *,
        boot: int = 0,
        physical: list[int] | None = None,
        observer: Observer | None = None,
    ):
        self.cfg = cfg
        self.clock_hz = cfg.clock_hz
        self.capacity = cfg.slots
        self.record = record
        self.boot = boot
        self.observer = observer
        self.queue: deque[Item] = deque()
        self.queued_ticks = 0  # segments and dwells in the queue
        self.block_ends = 0  # queued items that end a block
        self.flush_item = 0  # FLUSH: items up to this number may start at once
        self.start_ticks = round(cfg.start_s * cfg.clock_hz)
        self.last_arrival = -math.inf  # device time of the latest enqueue or FLUSH
        self.current: Item | None = None
        self.cur_end = 0.0
        self.cur_start = 0.0
        self._abort: tuple[float, int, int] | None = None  # (tau, axis, physical) of an endstop hit
        self.pos = [0, 0, 0, 0]
        self.tail_pos = [0, 0, 0, 0]  # where everything queued will have left the axes
        phys = list(physical if physical is not None else cfg.boot_physical)
        self.offset = phys  # physical = pos + offset (modules only)
        self.items_received = self.items_done = 0
        self.segments_received = self.segments_done = 0
        self.motion_ticks = 0
        self.at_rest = True
        self.t_free = 0.0
        self.fault = 0
        self.last_error = 0
        self.latched = 0  # a thermal fault: only a reset clears it
        self.estopped = False
        self.enabled_mask = self.homed_mask = 0
        self.tail_homed = 0  # homed once everything queued has run
        self.limits = SoftLimits()
        self.fan = 0
        self.heaters = [Heater(cfg.hotend), Heater(cfg.bed)]
        self.max_dc = [round(cfg.hotend.max_c * 10), round(cfg.bed.max_c * 10)]
        self.settled = True
        self.halt_at: int | None = None
        self.halted = False
        self.heater_fail_at: float | None = None
        self.sensor_fault: tuple[float, str] | None = None  # (device time, open / short)
        self.overflow_rejects = 0
        # a ring of schedule-block entries too full for the largest block (3.2): the host
        # may hold one back, so the queue starts (firmware_protocol/device/block_store.py)
        self.ring_full = False

    # ------------------------------------------------------------------ state

    def free_slots(self) -> int:
        return self.capacity - len(self.queue) - (self.current is not None)

    def flags(self) -> int:
        f = 0
        cur = self.current
        if (cur is not None and cur.kind in TIMED) or not self.at_rest:
            f |= _MOVING
        if self.fault:
            f |= _FAULT
        if self.estopped:
            f |= _ESTOP
        if self.homed_mask == 0b111:
            f |= _HOMED
        if self.enabled_mask:
            f |= _ENABLED
        if self.heaters[0].target > 0 or self.heaters[1].target > 0:
            f |= _HEATING
        if cur is not None and cur.kind in HOLDING:
            f |= _WAITING
        return f

    def active(self) -> bool:
        """Anything to do: motion executing or queued, a heater on (the watchdog guards it)."""
        return self.current is not None or bool(self.queue) or self.heating()

    def heating(self) -> bool:
        """A heater target above 0 or an autotune running (the heater lease guards them)."""
        return any(h.target > 0 or h.tune is not None for h in self.heaters)

    def buffered_ticks(self, T: float) -> int:
        """Queued motion not yet executed: the rest of the current timed item and the queue."""
        rest = 0
        cur = self.current
        if cur is not None and cur.kind in TIMED and self.cur_end > T:
            rest = math.ceil((self.cur_end - T) * self.clock_hz)
        return min(U32, self.queued_ticks + rest)

    def clock(self, T: float) -> int:
        return int(T * self.clock_hz) & U32

    def steps_now(self, T: float) -> list[int]:
        cur = self.current
        if cur is None or cur.kind != SEG or self.cur_end <= self.cur_start:
            return list(self.pos)
        tau = (T - self.cur_start) / (cur.ticks / self.clock_hz)
        done = steps_done(cur.deltas, cur.ramp, tau)
        return [p + int(d) for p, d in zip(self.pos, done)]

    # ------------------------------------------------------------------ input

    def enqueue(self, item: Item, T: float) -> list[Message]:
        """Add one queued item (numbers already assigned). Returns reports."""
        if self.fault:
            self.items_done = item.item  # discarded while faulted
            return []
        kind = item.kind
        if kind == SEG:
            ticks, deltas = item.ticks, item.deltas
            refused = segment_refusal(
                ticks,
                deltas,
                item.ramp,
                self.tail_pos,
                homed=self.tail_homed,
                limits=self.limits,
                clock_hz=self.clock_hz,
                max_step_rate=self.cfg.max_step_rate,
                total_step_rate=self.cfg.total_step_rate,
                scheduled=item.arg[0] if item.arg else 0,
            )
            if refused is not None:  # before any of it moves
                return [self.fail(refused[0], item.item, item.seg, T, *refused[1:])]
            self.tail_pos = [p + d for p, d in zip(self.tail_pos, deltas)]
            self.queued_ticks += ticks
        elif kind == DWELL:
            self.queued_ticks += item.ticks
        elif kind == SETPOS:
            self.tail_pos = list(item.arg)
        elif kind == HOME:
            mask, targets = item.arg
            for k in range(3):
                if mask >> k & 1:
                    self.tail_pos[k] = targets[k]
            self.tail_homed |= mask
        elif kind in (HEATER, TUNE):
            hid, target = item.arg[:2]
            if target > self.max_dc[hid]:
                return [self.fail(ErrorCode.HEATER_RANGE, item.item, 0, T, hid, target)]
        if _ends_block(item):
            self.block_ends += 1
        self.queue.append(item)
        self.last_arrival = T
        return []

    def flush(self, T: float) -> None:
        """FLUSH: the motion queued so far may start now (later items follow the rule)."""
        self.flush_item = self.items_received
        self.last_arrival = T

    def fail(
        self,
        code: int,
        item: int,
        segment: int,
        T: float,
        axis: int = 0xFF,
        value: int = 0,
        *,
        heaters_off: bool | None = None,
    ) -> Error:
        """The one shutdown path: stop now, flush the queue, keep the motors enabled, record
        the cause and return its report (a second fault too); heaters off for thermal faults,
        the watchdog, the heater lease and an e-stop (unless ``heaters_off`` says otherwise);
        a thermal fault latches until a reset."""
        if self.current is not None and self.current.kind == SEG and self.cur_end > T:
            cur = self.current
            tau = (T - self.cur_start) / (cur.ticks / self.clock_hz)
            self._apply_partial(cur, tau, ErrorCode(code).name.lower())
        self.fault = int(code)
        self.last_error = int(code)
        if code in THERMAL_ERRORS:
            self.latched = int(code)
        self.queue.clear()
        self.queued_ticks = 0
        self.block_ends = 0
        self.current = None
        self.at_rest = True
        self.t_free = T
        self.items_done = self.items_received
        self.tail_pos = list(self.pos)
        self.tail_homed = self.homed_mask
        if heaters_off is None:
            heaters_off = code in HEATERS_OFF
        for h in self.heaters:
            if heaters_off or h.tune is not None:  # an autotune never outlives its queue item
                h.off(T)
        return Error(int(code), item, segment, axis, max(-MAX_DELTA, min(MAX_DELTA, value)))

    def clear_fault(self) -> bool:
        """Leave the fault state (False: not faulted, or a latched thermal fault)."""
        if not self.fault or self.latched:
            return False
        self.fault = 0
        self.estopped = False
        return True

    # ------------------------------------------------------------------ execution

    def _may_start(self) -> bool:
        """The start rule from rest (PROTOCOL.md 5.4), O(1)."""
        return (
            self.block_ends > 0
            or self.queued_ticks >= self.start_ticks
            or self.free_slots() <= 0
            or self.ring_full
            or self.queue[0].item <= self.flush_item
        )

    def next_start(self) -> float | None:
        """Device time at which the head of the queue will start if nothing arrives (None:
        it waits for the host)."""
        if self.current is not None or not self.queue or self.fault or self.halted:
            return None
        head = self.queue[0]
        if head.kind == SEG and self.at_rest:
            return max(self.t_free, self.last_arrival) if self._may_start() else None
        return max(self.t_free, head.arrival)

    def advance(self, T: float) -> list[Message]:
        reports: list[Message] = []
        if self.heater_fail_at is not None and self.heater_fail_at <= T:
            self.heaters[HOTEND].element_ok = False
        if self.sensor_fault is not None and self.sensor_fault[0] <= T:
            self.heaters[HOTEND].sensor = self.sensor_fault[1]
        queue = self.queue
        while not self.halted and not self.fault:
            cur = self.current
            if cur is not None:
                if cur.kind in HOLDING:
                    reports += self._heaters_to(T)
                    h = self.heaters[cur.arg[0]]
                    if self.fault or (
                        h.tune is not None
                        if cur.kind == TUNE
                        else h.target > 0 and abs(h.reading - h.target) > cur.arg[1] / 10.0
                    ):
                        break
                    self.cur_end = T
                if self.cur_end > T:
                    break
                reports += self._complete(self.cur_end)
                continue
            if not queue:
                break
            head = queue[0]
            if head.kind == SEG and self.at_rest:
                if not self._may_start():
                    break
                start = max(self.t_free, self.last_arrival)
            else:
                start = max(self.t_free, head.arrival)
            if start > T:
                break
            queue.popleft()
            if head.kind in (SEG, DWELL):
                self.queued_ticks -= head.ticks
            if _ends_block(head):
                self.block_ends -= 1
            reports += self._start(head, start)
        reports += self._heaters_to(T)  # in every state: thermal protection never pauses
        if (
            self.observer is not None
            and not self.settled
            and self.current is None
            and not queue
            and self.at_rest
            and self.t_free + self.cfg.settle_s <= T
        ):
            self.settled = True
            self.observer.on_settled(tuple(self.pos), self.t_free + self.cfg.settle_s)
        return reports

    def _heaters_to(self, T: float) -> list[Message]:
        """Heater reports up to ``T``; a thermal fault is one even when already faulted."""
        out: list[Message] = []
        for kind, hid, v in heater_outcomes(self.heaters, T):
            if kind == "reached":
                out.append(Event(EventCode.HEATER_REACHED, self.items_done, (hid, *v)))
            elif kind == "tuned":  # the gains are applied; the AUTOTUNE item is the current one
                item = self.current.item if self.current is not None else self.items_done
                out.append(Event(EventCode.AUTOTUNE_DONE, item, (hid, *v)))
            else:
                out.append(self.fail(v[0], self.items_done, self.segments_done, T, hid, v[1]))
        return out

    def _start(self, it: Item, t: float) -> list[Message]:
        self.settled = False
        clock = self.clock_hz
        kind = it.kind
        if kind == SEG:
            phys = [self.pos[k] + self.offset[k] for k in range(3)]
            self._abort = switch_crossing(phys, it.deltas, it.ramp, self.cfg.overtravel_steps)
            deltas = it.deltas
            if deltas[0] or deltas[1] or deltas[2] or deltas[3]:
                self.enabled_mask |= sum(1 << k for k, d in enumerate(deltas) if d)
            self.current, self.cur_start = it, t
            tau = self._abort[0] if self._abort else 1.0
            self.cur_end = t + tau * it.ticks / clock
            return []
        if kind in (DWELL, HOME, WAIT, TUNE):
            self.at_rest = True
            ticks = it.ticks
            if kind == TUNE:
                hid, target, cycles = it.arg
                self.heaters[hid].start_tune(target / 10.0, cycles, t)
            if kind == HOME:
                mask = it.arg[0]
                dist = max(
                    (abs(self.pos[k] + self.offset[k]) for k in range(3) if mask >> k & 1),
                    default=0,
                )
                if dist > self.cfg.homing_max_steps:
                    return [self.fail(ErrorCode.HOMING_FAILED, it.item, 0, t, 0xFF, dist)]
                ticks = math.ceil(dist / self.cfg.homing_rate * clock)
                it = it._replace(ticks=ticks)
                self.enabled_mask |= mask
            self.current, self.cur_start = it, t
            self.cur_end = t + ticks / clock if kind not in HOLDING else math.inf
            return []
        reports: list[Message] = []
        arg = it.arg
        if kind == SETPOS:
            for k in range(4):
                if k < 3:
                    self.offset[k] += self.pos[k] - arg[k]
                self.pos[k] = arg[k]
        elif kind == ENABLE:
            self.enabled_mask = arg[0] & 0xF
        elif kind == HEATER:
            hid, target = arg
            reports += self._heaters_to(t)
            self.heaters[hid].set_target(target / 10.0, t)
        elif kind == FAN and arg[0] == 0:
            self.fan = arg[1]
        self.items_done = it.item
        self.t_free = max(self.t_free, t)
        if not self.at_rest and not self.queue and self.current is None:
            reports.append(self.fail(ErrorCode.UNDERRUN, it.item, self.segments_done, t))
        return reports

    def _apply_partial(self, it: Item, tau: float, error: str) -> None:
        done = steps_done(it.deltas, it.ramp, tau)
        self.pos = [p + int(d) for p, d in zip(self.pos, done)]
        self.motion_ticks += round(tau * it.ticks)
        self.record.append(it.seg, self.pos, self.motion_ticks, self.boot, error)

    def _complete(self, t: float) -> list[Message]:
        it = self.current
        assert it is not None
        self.current = None
        self.t_free = t
        kind = it.kind
        if kind == SEG:
            if self._abort is not None:
                tau, axis, phys = self._abort
                self._abort = None
                self.current = it  # so fail() applies the partial segment
                self.cur_end = math.inf
                return [
                    self.fail(
                        ErrorCode.ENDSTOP_HIT,
                        it.item,
                        it.seg,
                        self.cur_start + tau * it.ticks / self.clock_hz,
                        axis,
                        phys,
                    )
                ]
            d = it.deltas
            p = self.pos
            pos = [p[0] + d[0], p[1] + d[1], p[2] + d[2], p[3] + d[3]]
            self.pos = pos
            self.motion_ticks += it.ticks
            self.segments_done = it.seg
            self.items_done = it.item
            self.record.append(it.seg, pos, self.motion_ticks, self.boot)
            self.at_rest = it.ramp == RAMP_TO_REST or not (d[0] or d[1] or d[2] or d[3])
            if self.halt_at is not None and self.segments_done >= self.halt_at:
                self.halted = True
                return []
            if not self.at_rest and not self.queue:
                return [self.fail(ErrorCode.UNDERRUN, it.item, it.seg, t)]
            return []
        self.items_done = it.item
        if kind == DWELL:
            self.motion_ticks += it.ticks
        elif kind == HOME:
            self.motion_ticks += it.ticks
            mask, targets = it.arg
            for k in range(3):
                if mask >> k & 1:
                    self.pos[k] = targets[k]
                    self.offset[k] = -targets[k]  # the switch is physical 0
            self.homed_mask |= mask
            return [Event(EventCode.HOMED, it.item, tuple(self.pos[:3]))]
        return []

    def stop(
        self,
        T: float,
        code: int,
        *,
        keep_heaters: bool = False,
        keep_motors: bool = False,
        value: int = 0,
    ) -> list[Message]:
        """Stop now (mid-segment if need be) and flush: an e-stop or the host watchdog."""
        reports = self.advance(T)
        reports.append(
            self.fail(
                code,
                self.items_done,
                self.segments_done,
                T,
                value=value,
                heaters_off=not keep_heaters,
            )
        )
        if not keep_motors:
            self.enabled_mask = 0
            self.homed_mask = self.tail_homed = 0  # released: positions no longer trustworthy
        return reports
