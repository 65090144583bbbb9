"""The firmware's machine model: move queue, step positions, timing, endstops, heaters.

Driven by device time ``T`` (seconds). Items are executed strictly in order;
segments, dwells and homing take time, the other items are instantaneous. The
motion clock (``motion_ticks``) only advances with executed durations, so the
record is the same whatever the link did. Reports (errors, events) are returned
as protocol messages for the protocol layer to send.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from itertools import islice

from firmware_protocol.device.config import SimConfig
from firmware_protocol.device.heaters import Heater
from firmware_protocol.device.record import record_entry
from firmware_protocol.messages import BED, HOTEND, Error, ErrorCode, Event, EventCode, Flag
from firmware_protocol.segments import RAMP_TO_REST, ramp_share, steps_done

SEG, DWELL, HOME, SETPOS, ENABLE, HEATER, FAN, WAIT = range(8)
TIMED = (SEG, DWELL, HOME)
_MOVING, _FAULT, _ESTOP, _HOMED, _ENABLED, _HEATING, _WAITING = (
    int(Flag.MOVING),
    int(Flag.FAULT),
    int(Flag.ESTOP),
    int(Flag.HOMED),
    int(Flag.ENABLED),
    int(Flag.HEATING),
    int(Flag.WAITING),
)


@dataclass(slots=True)
class Item:
    kind: int
    item: int
    arrival: float  # device time
    seg: int = 0
    ticks: int = 0
    deltas: tuple[int, int, int, int] = (0, 0, 0, 0)
    ramp: int = -1
    arg: tuple = ()


class Machine:
    def __init__(
        self, cfg: SimConfig, record: list[dict], *, boot: int = 0, physical=None, observer=None
    ):
        self.cfg = cfg
        self.record = record
        self.boot = boot
        self.observer = observer
        self.queue: deque[Item] = deque()
        self.current: Item | None = None
        self.cur_end = 0.0
        self.cur_start = 0.0
        self._abort: tuple[float, int, int] | None = None  # (tau, axis, physical) of an endstop hit
        self.pos = [0, 0, 0, 0]
        phys = list(physical if physical is not None else cfg.boot_physical)
        self.offset = phys  # physical = pos + offset (modules only)
        self.items_received = self.items_done = 0
        self.segments_received = self.segments_done = 0
        self.motion_ticks = 0
        self.at_rest = True
        self.t_free = 0.0
        self.last_enqueue_T = -math.inf
        self.last_enqueue_link = -math.inf
        self.fault = 0
        self.last_error = 0
        self.estopped = False
        self.enabled_mask = self.homed_mask = 0
        self.fan = 0
        self.heaters = [Heater(cfg.hotend), Heater(cfg.bed)]
        self.settled = True
        self.halt_at: int | None = None
        self.halted = False
        self.heater_fail_at: float | None = None
        self.overflow_rejects = 0

    # ------------------------------------------------------------------ state

    def free_slots(self) -> int:
        return self.cfg.queue_capacity - len(self.queue) - (self.current is not None)

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
        if cur is not None and cur.kind == WAIT:
            f |= _WAITING
        return f

    def completion_time(self, k: int) -> float:
        """Device time by which ``k`` (>= 1) more items will have completed if the queue runs on."""
        if self.current is None:
            return math.inf
        t = self.cur_end
        clock = self.cfg.clock_hz
        for it in islice(self.queue, max(0, k - 1)):
            if it.kind in (WAIT, HOME):
                return math.inf
            t += it.ticks / clock if it.kind in (SEG, DWELL) else 0.0
        return t

    def steps_now(self, T: float) -> list[int]:
        cur = self.current
        if cur is None or cur.kind != SEG or self.cur_end <= self.cur_start:
            return list(self.pos)
        tau = (T - self.cur_start) / (cur.ticks / self.cfg.clock_hz)
        done = steps_done(cur.deltas, cur.ramp, tau)
        return [p + int(d) for p, d in zip(self.pos, done)]

    # ------------------------------------------------------------------ input

    def enqueue(self, item: Item, T: float, link_now: float) -> list:
        """Add one queued item (numbers already assigned). Returns reports."""
        if self.fault:
            self.items_done = item.item  # discarded while faulted
            return []
        if item.kind == SEG:
            r = 0.5 if item.ramp < 0 else item.ramp / 255.0
            factor = max(2 * r, 2 - 2 * r) * self.cfg.clock_hz / item.ticks
            for axis, d in enumerate(item.deltas):
                rate = abs(d) * factor
                if rate > self.cfg.max_step_rate * (1 + 1e-9):
                    return [self.fail(ErrorCode.STEP_RATE, item.item, item.seg, T, axis, int(rate))]
        if item.kind == HEATER and item.arg[1] > 10 * self.heaters[item.arg[0]].model.max_c:
            return [self.fail(ErrorCode.HEATER_RANGE, item.item, 0, T, item.arg[0], item.arg[1])]
        self.queue.append(item)
        self.last_enqueue_T = T
        self.last_enqueue_link = link_now
        return []

    def fail(
        self, code: int, item: int, segment: int, T: float, axis: int = 0xFF, value: int = 0
    ) -> Error:
        """Enter the fault state: stop, flush the queue; heaters off for thermal faults and e-stop."""
        if self.current is not None and self.current.kind == SEG and self.cur_end > T:
            cur = self.current
            tau = (T - self.cur_start) / (cur.ticks / self.cfg.clock_hz)
            self._apply_partial(cur, tau, ErrorCode(code).name.lower())
        self.fault = int(code)
        self.last_error = int(code)
        self.queue.clear()
        self.current = None
        self.at_rest = True
        self.t_free = T
        self.items_done = self.items_received
        if code in (ErrorCode.THERMAL_RUNAWAY, ErrorCode.OVERTEMP, ErrorCode.ESTOP):
            for h in self.heaters:
                h.off(T)
        return Error(int(code), item, segment, axis, value)

    def clear_fault(self) -> bool:
        if not self.fault:
            return False
        self.fault = 0
        self.estopped = False
        return True

    # ------------------------------------------------------------------ execution

    def _may_start(self, link_now: float) -> bool:
        need = (
            self.cfg.start_buffer_s * self.cfg.speedup * self.cfg.clock_hz
        )  # real-time worth of motion
        total = 0
        for it in self.queue:
            if it.kind != SEG:
                return True
            total += it.ticks
            if it.ramp == RAMP_TO_REST or not any(it.deltas) or total >= need:
                return True
        if self.free_slots() <= 0:
            return True
        return link_now >= self.last_enqueue_link + self.cfg.start_delay_s

    def advance(self, T: float, link_now: float) -> list:
        reports: list = []
        if self.heater_fail_at is not None and self.heater_fail_at <= T:
            self.heaters[HOTEND].element_ok = False
        while not self.halted and not self.fault:
            cur = self.current
            if cur is not None:
                if cur.kind == WAIT:
                    reports += self._heaters_to(T)
                    h = self.heaters[cur.arg[0]]
                    if self.fault or abs(h.temp - h.target) > cur.arg[1] / 10.0:
                        break
                    self.cur_end = T
                if self.cur_end > T:
                    break
                reports += self._complete(self.cur_end)
                continue
            if not self.queue:
                break
            head = self.queue[0]
            start = self.t_free if self.t_free >= self.last_enqueue_T else T
            if head.kind == SEG and self.at_rest and not self._may_start(link_now):
                break
            self.queue.popleft()
            reports += self._start(head, start)
        if not self.fault:
            reports += self._heaters_to(T)
        if (
            self.observer is not None
            and not self.settled
            and self.current is None
            and not self.queue
            and self.at_rest
            and self.t_free + self.cfg.settle_s <= T
        ):
            self.settled = True
            self.observer.on_settled(tuple(self.pos), self.t_free + self.cfg.settle_s)
        return reports

    def _heaters_to(self, T: float) -> list:
        out: list = []
        for hid, h in enumerate(self.heaters):
            for ev in h.advance(T):
                if ev == "reached":
                    out.append(
                        Event(EventCode.HEATER_REACHED, self.items_done, (hid, round(h.temp * 10)))
                    )
                elif not self.fault:
                    code = ErrorCode.THERMAL_RUNAWAY if ev == "runaway" else ErrorCode.OVERTEMP
                    out.append(
                        self.fail(
                            code, self.items_done, self.segments_done, T, hid, round(h.temp * 10)
                        )
                    )
        return out

    def _start(self, it: Item, t: float) -> list:
        self.settled = False
        clock = self.cfg.clock_hz
        if it.kind == SEG:
            self._abort = self._endstop_crossing(it)
            self.enabled_mask |= sum(1 << k for k, d in enumerate(it.deltas) if d)
            self.current, self.cur_start = it, t
            tau = self._abort[0] if self._abort else 1.0
            self.cur_end = t + tau * it.ticks / clock
            return []
        if it.kind in (DWELL, HOME, WAIT):
            self.at_rest = True
            if it.kind == HOME:
                mask = it.arg[0]
                dist = max(
                    (abs(self.pos[k] + self.offset[k]) for k in range(3) if mask >> k & 1),
                    default=0,
                )
                if dist > self.cfg.homing_max_steps:
                    return [self.fail(ErrorCode.HOMING_FAILED, it.item, 0, t, 0xFF, dist)]
                it.ticks = math.ceil(dist / self.cfg.homing_rate * clock)
                self.enabled_mask |= mask
            self.current, self.cur_start = it, t
            self.cur_end = t + it.ticks / clock if it.kind != WAIT else math.inf
            return []
        reports: list = []
        if it.kind == SETPOS:
            for k in range(4):
                if k < 3:
                    self.offset[k] += self.pos[k] - it.arg[k]
                self.pos[k] = it.arg[k]
        elif it.kind == ENABLE:
            self.enabled_mask = it.arg[0] & 0xF
        elif it.kind == HEATER:
            hid, target = it.arg
            reports += self._heaters_to(t)
            self.heaters[hid].set_target(target / 10.0, t)
        elif it.kind == FAN:
            self.fan = it.arg[1]
        self.items_done = it.item
        self.t_free = max(self.t_free, t)
        if not self.at_rest and not self.queue and self.current is None:
            reports.append(self.fail(ErrorCode.UNDERRUN, it.item, self.segments_done, t))
        return reports

    def _endstop_crossing(self, it: Item) -> tuple[float, int, int] | None:
        limit = self.cfg.overtravel_steps
        best = None
        for k in range(3):
            d = it.deltas[k]
            start = self.pos[k] + self.offset[k]
            if d > 0 and start <= limit < start + d:
                x = (limit + 1 - start - 0.5) / d  # normalised position of the offending step
                r = float(ramp_share(it.ramp))
                tau = x / (r + math.sqrt(r * r + (1 - 2 * r) * x))
                if best is None or tau < best[0]:
                    best = (tau, k, limit + 1)
        return best

    def _apply_partial(self, it: Item, tau: float, error: str) -> None:
        done = steps_done(it.deltas, it.ramp, tau)
        self.pos = [p + int(d) for p, d in zip(self.pos, done)]
        part = round(tau * it.ticks)
        self.motion_ticks += part
        self.record.append(
            record_entry(
                it.seg, list(self.pos), self.motion_ticks, self.cfg.clock_hz, self.boot, error
            )
        )

    def _complete(self, t: float) -> list:
        it = self.current
        assert it is not None
        self.current = None
        self.t_free = t
        if it.kind == SEG:
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
                        self.cur_start + tau * it.ticks / self.cfg.clock_hz,
                        axis,
                        phys,
                    )
                ]
            d = it.deltas
            p = self.pos
            self.pos = [p[0] + d[0], p[1] + d[1], p[2] + d[2], p[3] + d[3]]
            self.motion_ticks += it.ticks
            self.segments_done = it.seg
            self.items_done = it.item
            self.record.append(
                record_entry(
                    it.seg, list(self.pos), self.motion_ticks, self.cfg.clock_hz, self.boot
                )
            )
            self.at_rest = it.ramp == RAMP_TO_REST or not any(d)
            if self.halt_at is not None and self.segments_done >= self.halt_at:
                self.halted = True
                return []
            if not self.at_rest and not self.queue:
                return [self.fail(ErrorCode.UNDERRUN, it.item, it.seg, t)]
            return []
        self.items_done = it.item
        if it.kind == DWELL:
            self.motion_ticks += it.ticks
        elif it.kind == HOME:
            self.motion_ticks += it.ticks
            mask, targets = it.arg
            for k in range(3):
                if mask >> k & 1:
                    self.pos[k] = targets[k]
                    self.offset[k] = -targets[k]  # the switch is physical 0
            self.homed_mask |= mask
            return [Event(EventCode.HOMED, it.item, tuple(self.pos[:3]))]
        return []

    def estop(self, T: float) -> list:
        """Stop now (mid-segment if need be), flush, heaters off; reports include the ESTOP error."""
        reports = self.advance(T, -math.inf)
        reports.append(self.fail(ErrorCode.ESTOP, self.items_done, self.segments_done, T))
        self.estopped = True
        self.enabled_mask = 0
        self.homed_mask = 0  # motors released: positions are no longer trustworthy
        return reports


__all__ = [
    "BED",
    "DWELL",
    "ENABLE",
    "FAN",
    "HEATER",
    "HOME",
    "HOTEND",
    "SEG",
    "SETPOS",
    "WAIT",
    "Item",
    "Machine",
]
