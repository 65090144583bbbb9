"""The simulated device: the firmware's protocol side around the machine model.

``SimDevice.step(now, data)`` is the whole main loop of the firmware: run the
machine up to ``now``, take in received bytes, and return the frames to write.
``next_deadline(now)`` says when ``step`` must run again if nothing arrives.
``now`` is link time in seconds; device time is ``now * config.speedup``.
"""

from __future__ import annotations

import math

from firmware_protocol.device import machine as m
from firmware_protocol.device.config import SimConfig
from firmware_protocol.device.faults import FaultSpec
from firmware_protocol.device.machine import Item, Machine
from firmware_protocol.endpoint import Endpoint
from firmware_protocol.messages import (
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    Boot,
    BootCause,
    ClearFault,
    Dwell,
    EmergencyStop,
    Enable,
    ErrorCode,
    EstopAck,
    Event,
    EventCode,
    Flag,
    Flow,
    GetStatus,
    Hello,
    Home,
    Ident,
    Identify,
    Message,
    MessageError,
    Segment,
    SetFan,
    SetHeater,
    SetPosition,
    Status,
    WaitHeater,
    decode_messages,
    encode_message,
)
from firmware_protocol.messages import Error as ErrorReport
from firmware_protocol.segments import SegmentContext

MAX_REPORT_BACKLOG = 256


class SimDevice:
    """The simulated firmware. ``record`` lists every executed segment (see record.py)."""

    def __init__(
        self, config: SimConfig | None = None, faults: FaultSpec | None = None, observer=None
    ):
        self.config = config or SimConfig()
        self.faults = faults or FaultSpec()
        self.observer = observer
        self.record: list[dict] = []
        if hasattr(
            observer, "attach_record"
        ):  # the observer may read motion directions from the record
            observer.attach_record(self.record)
        self.boots = 0
        self.reset_times: list[float] = []  # link times of simulated resets
        self.stalled = False
        self._now = 0.0
        self._reset_done = False
        self._prev: tuple[int, int] | None = None
        self._start_boot(BootCause.POWER_ON, physical=None)

    # ------------------------------------------------------------------ boot / session

    def _start_boot(self, cause: int, physical) -> None:
        cfg = self.config
        self.cause = int(cause)
        self.boot_id = (cfg.seed * 2654435761 + self.boots * 40503 + 0x5EED) & 0xFFFFFFFF
        self.machine = Machine(
            cfg, self.record, boot=self.boots, physical=physical, observer=self.observer
        )
        if self.faults.reset_after and not self._reset_done:
            self.machine.halt_at = self.faults.reset_after
        elif self.faults.stall_after:
            self.machine.halt_at = self.faults.stall_after
        if self.faults.heater_fail_after is not None:
            self.machine.heater_fail_at = self.faults.heater_fail_after
        self.endpoint = Endpoint(
            window=cfg.window,
            accept=self._accept,
            flow=self._flow_payload,
            rto_initial=0.25,
            rto_floor=0.02,
            rto_ceiling=1.0,
        )
        self.synced = False
        self.nonce: int | None = None
        self.ctx = SegmentContext()
        self._boot_sent = -math.inf
        self._flow_sent: tuple = ()
        self._flow_free_sent = 0
        self._flow_step = max(1, cfg.queue_capacity // 8)
        self._flow_time = -math.inf

    def reboot(self, now: float, cause: int = BootCause.WATCHDOG) -> None:
        """Simulated reset: the queue, positions and session are lost; the carriages stay put.

        The counters of the last boot survive (as in no-init RAM) and are announced.
        """
        old = self.machine
        self.reset_times.append(now)
        self._prev = (old.items_done, old.segments_done)
        physical = [old.pos[k] + old.offset[k] for k in range(3)]
        self.boots += 1
        self._start_boot(cause, physical)
        self.machine.t_free = self.device_time(now)

    def device_time(self, now: float) -> float:
        return now * self.config.speedup

    def _boot_message(self) -> Boot:
        prev = self._prev or (0, 0)
        return Boot(
            self.boot_id,
            self.cause,
            PROTOCOL_MAJOR,
            PROTOCOL_MINOR,
            int(self._prev is not None),
            *prev,
        )

    def ident(self, nonce: int) -> Ident:
        c, mc = self.config, self.machine
        return Ident(
            nonce,
            PROTOCOL_MAJOR,
            PROTOCOL_MINOR,
            self.boot_id,
            c.firmware_name,
            c.firmware_version,
            4,
            c.queue_capacity,
            c.clock_hz,
            c.max_step_rate,
            c.max_payload,
            2,
            1,
            mc.items_received,
            mc.items_done,
            mc.segments_received,
            mc.segments_done,
        )

    def status(self) -> Status:
        mc = self.machine
        T = self.device_time(self._now)
        h, b = mc.heaters
        ep = self.endpoint
        return Status(
            mc.flags() | (Flag.SYNCED if self.synced else 0),
            max(0, mc.free_slots()),
            mc.items_done,
            mc.segments_done,
            mc.motion_ticks,
            tuple(mc.steps_now(T)),
            round(h.temp * 10),
            round(h.target * 10),
            round(b.temp * 10),
            round(b.target * 10),
            mc.fan,
            mc.enabled_mask,
            mc.homed_mask,
            mc.last_error,
            ep.bad_frames,
            ep.retransmits,
            ep.counters.naks_sent,
            ep.counters.duplicates,
        )

    # ------------------------------------------------------------------ main loop

    def step(self, now: float, data: bytes = b"") -> list[bytes]:
        """Run to ``now``, take in ``data``, return the frames to write (one bytes object each)."""
        self._now = now
        T = self.device_time(now)
        self._report(self.machine.advance(T, now))
        if self.machine.halted:
            if self.faults.reset_after and not self._reset_done:
                self._reset_done = True
                self.reboot(now)
            else:
                self.stalled = True
        if self.stalled:
            return []
        if data:
            for inc in self.endpoint.feed(data, now):
                if inc.kind == "urgent":
                    self._urgent(inc.payload, now)
            self._report(self.machine.advance(T, now))
        if self.synced and self._flow_wanted(now):
            self.endpoint.request_ack()
        if not self.synced and now >= self._boot_sent + self.config.boot_announce_s:
            self._announce_boot(now)
        return self.endpoint.flush(now)

    def next_deadline(self, now: float) -> float | None:
        """Link time at which ``step`` has work even if no byte arrives (None: never)."""
        if self.stalled:
            return None
        cands: list[float] = []
        ep = self.endpoint.next_deadline()
        if ep is not None:
            cands.append(max(ep, now))
        mc, sp, cfg = self.machine, self.config.speedup, self.config
        cur = mc.current
        flow_due = self._flow_time + cfg.flow_interval_s
        if cur is not None:
            if cur.kind == m.WAIT:
                cands.append(now + 0.2 / sp)
            elif not mc.queue:
                cands.append(mc.cur_end / sp)
            else:  # when enough slots will have freed to be worth a FLOW report
                k = self._flow_free_sent + self._flow_step - mc.free_slots()
                cands.append(max(mc.cur_end / sp, min(flow_due, mc.completion_time(k) / sp)))
        elif mc.queue and not mc.fault:
            cands.append(mc.last_enqueue_link + cfg.start_delay_s)
        if self.synced and (mc.items_done, mc.flags()) != self._flow_sent:
            cands.append(flow_due)
        if any(h.target > 0 for h in mc.heaters):
            cands.append(now + 0.5 / sp)
        if mc.heater_fail_at is not None and mc.heater_fail_at / sp > now:
            cands.append(mc.heater_fail_at / sp)
        if self.observer is not None and not mc.settled and cur is None:
            cands.append((mc.t_free + cfg.settle_s) / sp)
        if not self.synced:
            cands.append(self._boot_sent + cfg.boot_announce_s)
        return max(now, min(cands)) if cands else None

    # ------------------------------------------------------------------ protocol handlers

    def _announce_boot(self, now: float) -> None:
        self._boot_sent = now
        self.endpoint.send_urgent(encode_message(self._boot_message()))

    def _flow_wanted(self, now: float) -> bool:
        """Unsolicited FLOW: an eighth of the queue freed, or any change after flow_interval_s."""
        mc = self.machine
        if (mc.items_done, mc.flags()) == self._flow_sent:
            return False
        return (
            mc.free_slots() >= self._flow_free_sent + self._flow_step
            or now >= self._flow_time + self.config.flow_interval_s
        )

    def _flow_payload(self) -> bytes:
        mc = self.machine
        self._flow_sent = (mc.items_done, mc.flags())
        self._flow_free_sent = mc.free_slots()
        self._flow_time = self._now
        return encode_message(
            Flow(mc.flags(), max(0, mc.free_slots()), mc.items_done, mc.segments_done)
        )

    def _report(self, reports: list[Message]) -> None:
        if not self.synced:
            return
        for r in reports:
            if len(self.endpoint.sender.backlog) < MAX_REPORT_BACKLOG or isinstance(r, ErrorReport):
                self.endpoint.send(encode_message(r))

    def _urgent(self, payload: bytes, now: float) -> None:
        try:
            msgs = decode_messages(payload, SegmentContext())
        except MessageError:
            return
        for msg in msgs:
            if isinstance(msg, Hello):
                if msg.major == PROTOCOL_MAJOR and (not self.synced or msg.nonce != self.nonce):
                    self.endpoint.reset_session()
                    self.ctx = SegmentContext()
                    self.synced = True
                    self.nonce = msg.nonce
                    self._flow_sent = ()
                self.endpoint.send_urgent(encode_message(self.ident(msg.nonce)))
            elif isinstance(msg, EmergencyStop):
                if not self.machine.estopped:
                    self._report(self.machine.estop(self.device_time(now)))
                mc = self.machine
                self.endpoint.send_urgent(encode_message(EstopAck(mc.items_done, mc.segments_done)))

    def _accept(self, payload: bytes) -> bool:
        """Called by the endpoint for each in-order DATA payload; False leaves it unacknowledged."""
        now = self._now
        if not self.synced:
            if now - self._boot_sent >= 0.05:
                self._announce_boot(now)
            return False
        work = self.ctx.copy()
        mc = self.machine
        T = self.device_time(now)
        try:
            msgs = decode_messages(payload, work)
        except MessageError:
            self._report(
                [mc.fail(ErrorCode.BAD_COMMAND, mc.items_received, mc.segments_received, T)]
            )
            return True
        queued = sum(1 for x in msgs if x.QUEUED)
        if queued > mc.free_slots() and not mc.fault:
            mc.overflow_rejects += 1
            return False
        self.ctx = work
        reports: list[Message] = []
        for msg in msgs:
            if msg.QUEUED:
                reports += self._enqueue(msg, T, now)
            elif isinstance(msg, GetStatus):
                reports.append(self.status())
            elif isinstance(msg, Identify):
                reports.append(self.ident(self.nonce or 0))
            elif isinstance(msg, ClearFault):
                if mc.clear_fault():
                    reports.append(Event(EventCode.FAULT_CLEARED, mc.items_done, ()))
            else:
                reports.append(
                    mc.fail(ErrorCode.BAD_COMMAND, mc.items_received, mc.segments_received, T)
                )
        self._report(reports)
        return True

    def _enqueue(self, msg: Message, T: float, now: float) -> list[Message]:
        mc = self.machine
        mc.items_received += 1
        n = mc.items_received
        if isinstance(msg, Segment):
            mc.segments_received += 1
            it = Item(m.SEG, n, T, mc.segments_received, msg.ticks, msg.deltas, msg.ramp)
        elif isinstance(msg, Dwell):
            it = Item(m.DWELL, n, T, ticks=msg.ticks)
        elif isinstance(msg, Home):
            it = Item(m.HOME, n, T, arg=(msg.mask & 0b111, msg.positions))
        elif isinstance(msg, SetPosition):
            it = Item(m.SETPOS, n, T, arg=msg.steps)
        elif isinstance(msg, Enable):
            it = Item(m.ENABLE, n, T, arg=(msg.mask,))
        elif isinstance(msg, SetHeater):
            if msg.heater > 1:
                return [mc.fail(ErrorCode.BAD_COMMAND, n, 0, T, msg.heater)]
            it = Item(m.HEATER, n, T, arg=(msg.heater, msg.target_dc))
        elif isinstance(msg, SetFan):
            it = Item(m.FAN, n, T, arg=(msg.fan, msg.value))
        elif isinstance(msg, WaitHeater):
            if msg.heater > 1:
                return [mc.fail(ErrorCode.BAD_COMMAND, n, 0, T, msg.heater)]
            it = Item(m.WAIT, n, T, arg=(msg.heater, msg.tolerance_dc))
        else:  # pragma: no cover - every QUEUED message is handled above
            return [mc.fail(ErrorCode.BAD_COMMAND, n, 0, T)]
        return mc.enqueue(it, T, now)
