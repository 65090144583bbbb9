"""The simulated device: the firmware's protocol side around the machine model.

``SimDevice.step(now, data)`` is the whole main loop of the firmware: run the
machine up to ``now``, take in received bytes, check the host watchdog, and return
the frames to write. ``next_deadline(now)`` says when ``step`` must run again if
nothing arrives. ``now`` is link time in seconds; device time is
``now * config.speedup``. Every field of every message is checked before it acts
(PROTOCOL.md section 8): a bad frame gets a NAK or an ERROR, never an exception.
"""

from __future__ import annotations

import math
import os
import secrets
from collections.abc import Callable

from firmware_protocol.device import queue_items as m
from firmware_protocol.device.block_store import BlockStore, block_needs
from firmware_protocol.device.config import SimConfig
from firmware_protocol.device.faults import FaultSpec
from firmware_protocol.device.flow_reports import FlowReports
from firmware_protocol.device.heater_control import PidGains
from firmware_protocol.device.machine import DeviceMachine, Observer
from firmware_protocol.device.queue_items import BadValue, item_of
from firmware_protocol.device.record import SegmentRecord
from firmware_protocol.device.schedules import schedule_refusal
from firmware_protocol.endpoint import Endpoint
from firmware_protocol.message_codec import decode_messages, encode_message
from firmware_protocol.messages import (
    MAX_EVENT_VALUES,
    MINOR_BUDGET,
    MINOR_RING,
    MINOR_SAFETY,
    MINOR_STEPPING,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    Boot,
    BootCause,
    Caps,
    ClearFault,
    Configure,
    EmergencyStop,
    ErrorCode,
    EstopAck,
    EstopFlag,
    Event,
    EventCode,
    Flag,
    Flush,
    GetCaps,
    GetStatus,
    Health,
    HeaterLease,
    Hello,
    Ident,
    Identify,
    Message,
    MessageError,
    Segment,
    SetLimits,
    SetPid,
    Status,
    StepBudget,
    Stepping,
)
from firmware_protocol.messages import Error as ErrorReport
from firmware_protocol.segments import SegmentContext

MAX_REPORT_BACKLOG = 256
HEATERS = 2
U32 = 0xFFFF_FFFF

assert MAX_EVENT_VALUES >= 3  # HOMED carries three positions


class SimDevice:
    """The simulated firmware. ``record`` lists every executed segment (see record.py);
    with ``record_path`` it is also streamed to that file as segments execute; with
    ``record_keep`` n it holds only about the newest n in memory (the file gets all)."""

    def __init__(
        self,
        config: SimConfig | None = None,
        faults: FaultSpec | None = None,
        observer: Observer | None = None,
        *,
        record_path: str | os.PathLike[str] | None = None,
        record_keep: int | None = None,
        on_notice: Callable[[str], None] | None = None,
    ):
        self.config = config or SimConfig()
        self.faults = faults or FaultSpec()
        self.observer = observer
        self.on_notice = on_notice
        self.record = SegmentRecord(record_path, clock_hz=self.config.clock_hz, keep=record_keep)
        attach = getattr(observer, "attach_record", None)
        if attach is not None:  # the observer may read motion directions from the record
            attach(self.record)
        self.boots = 0
        self.reset_times: list[float] = []  # link times of simulated resets
        self.stalled = False
        self.reports_dropped = 0
        self._now = 0.0
        self._reset_done = False
        self._prev: tuple[int, int] | None = None
        self._start_boot(BootCause.POWER_ON, physical=None)

    # ------------------------------------------------------------------ boot / session

    def _start_boot(self, cause: int, physical: list[int] | None) -> None:
        cfg = self.config
        self.cause = int(cause)
        old = getattr(self, "boot_id", 0)
        # new at every start of the device, a restart of the program included (a host
        # relies on it to tell a reset); never the previous one
        self.boot_id = old
        while self.boot_id in (0, old):
            self.boot_id = secrets.randbits(32)
        self.machine = DeviceMachine(
            cfg, self.record, boot=self.boots, physical=physical, observer=self.observer
        )
        # the ring of schedule-block entries (a step engine's; None: blocks need no room)
        self.ring = BlockStore(cfg.ring_entries, cfg.max_payload) if cfg.ring_entries else None
        if self.faults.reset_after and not self._reset_done:
            self.machine.halt_at = self.faults.reset_after
        elif self.faults.stall_after:
            self.machine.halt_at = self.faults.stall_after
        if self.faults.heater_fail_after is not None:
            self.machine.heater_fail_at = self.faults.heater_fail_after
        for kind in ("open", "short"):
            after = getattr(self.faults, f"thermistor_{kind}_after")
            if after is not None:
                self.machine.sensor_fault = (after, kind)
        if self.faults.hotend_start_c is not None:
            self.machine.heaters[0].warm_start(self.faults.hotend_start_c)
        self.endpoint = Endpoint(
            window=cfg.window,
            accept=self._accept,
            flow=self._flow_payload,
            rto_initial=0.05,
            rto_floor=0.02,
            rto_ceiling=0.25,
        )
        self.synced = False
        self.nonce: int | None = None
        self.session_minor = 0  # min(host minor, device minor) of the session
        self.ctx = SegmentContext(cycles_per_tick=self.config.cycles_per_tick)
        self._boot_sent = -math.inf
        self._open_session_state(-math.inf)

    def _open_session_state(self, now: float) -> None:
        cfg = self.config
        self.watchdog_ms = cfg.watchdog_ms
        self.machine.start_ticks = round(cfg.start_s * cfg.clock_hz)
        self.last_rx = now
        self.flow = FlowReports(
            round(cfg.flow_s * cfg.clock_hz), cfg.flow_interval_s, self.machine.capacity // 8
        )
        self.lease_ms = 0  # the session's heater lease (0: not armed)
        if self.ring is not None:
            self.ring.new_session()
        self.lease_until = math.inf

    def _flow_payload(self) -> bytes:
        """FLOW for an ACK or NAK, and RING after it (3.2, a device with a ring)."""
        flow = self.flow.payload(self.machine, self._now, self.device_time(self._now))
        ring = self._session_ring()
        return flow if ring is None else flow + encode_message(ring.report())

    def _session_ring(self) -> BlockStore | None:
        """The ring, its blocks freed to now, in a session that reports it (3.2)."""
        ring = self.ring
        if ring is None or self.session_minor < MINOR_RING:
            return None
        mc = self.machine
        ring.free_through(mc.segments_done, mc.current is None and not mc.queue)
        mc.ring_full = ring.short()  # the host may hold a block back: start
        return ring

    @property
    def flow_ticks(self) -> int:
        return self.flow.flow_ticks

    def reboot(self, now: float, cause: int = BootCause.WATCHDOG) -> None:
        """Simulated reset: the queue, positions and session are lost; the carriages stay put,
        their drivers held.

        The counters of the last boot survive (as in no-init RAM) and are announced.
        """
        old = self.machine
        self.reset_times.append(now)
        self._prev = (old.items_done, old.segments_done)
        physical = [old.pos[k] + old.offset[k] for k in range(3)]
        self.boots += 1
        self._start_boot(cause, physical)
        self.machine.t_free = self.device_time(now)
        # the drivers enabled before the reset stay enabled (the AVR's .init3 holds them
        # from the record in RAM): a cable robot must not drop its effector
        self.machine.enabled_mask = old.enabled_mask
        self._notice(f"reset ({BootCause(cause).name.lower()}), boot id {self.boot_id:#010x}")

    def device_time(self, now: float) -> float:
        return now * self.config.speedup

    def _notice(self, text: str) -> None:
        if self.on_notice is not None:
            self.on_notice(text)

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
            nonce=nonce,
            major=PROTOCOL_MAJOR,
            minor=PROTOCOL_MINOR,
            boot_id=self.boot_id,
            firmware_name=c.firmware_name,
            firmware_version=c.firmware_version,
            axes=4,
            queue_capacity=mc.capacity,
            clock_hz=c.clock_hz,
            cpu_hz=c.cpu_hz,
            max_step_rate=c.max_step_rate,
            max_payload=c.max_payload,
            rx_window=c.rx_window,
            heaters=HEATERS,
            fans=c.fans,
            hotend_max_dc=mc.max_dc[0],
            bed_max_dc=mc.max_dc[1],
            watchdog_ms=self.watchdog_ms,
            start_ticks=min(U32, mc.start_ticks),
            items_received=mc.items_received,
            items_done=mc.items_done,
            segments_received=mc.segments_received,
            segments_done=mc.segments_done,
            clock=mc.clock(self.device_time(self._now)),
        )

    def status(self) -> Status:
        mc = self.machine
        T = self.device_time(self._now)
        h, b = mc.heaters
        ep = self.endpoint
        steps = mc.steps_now(T)
        return Status(
            flags=mc.flags() | (Flag.SYNCED if self.synced else 0),
            queue_free=max(0, mc.free_slots()),
            items_received=mc.items_received,
            items_done=mc.items_done,
            segments_done=mc.segments_done,
            buffered_ticks=mc.buffered_ticks(T),
            motion_ticks=mc.motion_ticks & U32,
            clock=mc.clock(T),
            steps=(steps[0], steps[1], steps[2], steps[3]),
            hotend_dc=round(h.reading * 10),
            hotend_target_dc=round(h.target * 10),
            bed_dc=round(b.reading * 10),
            bed_target_dc=round(b.target * 10),
            fan=mc.fan,
            enabled_mask=mc.enabled_mask,
            homed_mask=mc.homed_mask,
            last_error=mc.last_error,
            bad_frames=ep.bad_frames & U32,
            retransmits=ep.retransmits & U32,
            naks_sent=ep.counters.naks_sent & U32,
            duplicates=ep.counters.duplicates & U32,
        )

    def health(self) -> Health:
        """The model issues every pulse at its exact time and reads without limit."""
        return Health(late_pulses=0, late_worst_us=0, rx_overruns=0, loop_worst_us=0)  # all exact

    def caps(self) -> Caps:
        c = self.config
        return Caps(
            c.min_segment_ticks,
            c.segment_rate,
            c.late_tolerance_us,
            c.schedule_tolerance_cycles,
            c.min_step_interval_cycles,
        )

    # ------------------------------------------------------------------ main loop

    def step(self, now: float, data: bytes = b"") -> list[bytes]:
        """Run to ``now``, take in ``data``, return the frames to write (one bytes object each)."""
        self._now = now
        T = self.device_time(now)
        mc = self.machine
        self._report(mc.advance(T))
        if mc.halted:
            if self.faults.reset_after and not self._reset_done:
                self._reset_done = True
                self.reboot(now)
                mc = self.machine
            else:
                self.stalled = True
        if self.stalled:
            return []
        if data:
            ep = self.endpoint
            before = ep.deframer.frames
            for inc in ep.feed(data, now):
                if inc.kind == "urgent":
                    self._urgent(inc.payload, now)
            if ep.deframer.frames > before:
                self.last_rx = now
            self._report(self.machine.advance(T))
        self._watchdog(now, T)
        ring = self._session_ring()
        if self.synced and (
            self.flow.wanted(self.machine, now, T) or (ring and ring.wants_report())
        ):
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
        if cur is not None:
            if cur.kind == m.WAIT:
                cands.append(now + 0.2 / sp)
            elif not mc.queue or (self.ring is not None and self.ring.may_hold_host):
                cands.append(mc.cur_end / sp)  # (a short ring frees room at its end)
        start = mc.next_start()
        if start is not None:
            cands.append(start / sp)
        if self.synced:
            flow = self.flow.due(mc, now, sp)
            if flow is not None:
                cands.append(flow)
            if mc.active():
                cands.append(self.last_rx + self.watchdog_ms / 1000.0)
            if mc.heating():
                cands.append(self.lease_until)
        if any(h.target > 0 for h in mc.heaters):
            cands.append(now + 0.5 / sp)
        if mc.heater_fail_at is not None and mc.heater_fail_at / sp > now:
            cands.append(mc.heater_fail_at / sp)
        if mc.sensor_fault is not None and mc.sensor_fault[0] / sp > now:
            cands.append(mc.sensor_fault[0] / sp)
        if self.observer is not None and not mc.settled and cur is None:
            cands.append((mc.t_free + cfg.settle_s) / sp)
        if not self.synced:
            cands.append(self._boot_sent + cfg.boot_announce_s)
        return max(now, min(cands)) if cands else None

    # ------------------------------------------------------------------ watchdog and flow

    def _watchdog(self, now: float, T: float) -> None:
        """In every state, faulted included: no valid frame for watchdog_ms while there is
        something to do, or the heater lease run out with a heater on: stop, heaters off,
        motors held (the one shutdown path)."""
        mc = self.machine
        if not self.synced:
            return
        if mc.active() and now - self.last_rx >= self.watchdog_ms / 1000.0:
            self._report(mc.stop(T, ErrorCode.WATCHDOG, keep_motors=True, value=self.watchdog_ms))
            self._notice(
                f"host watchdog: no valid frame for {self.watchdog_ms} ms; motion stopped after "
                f"segment {mc.segments_done}, heaters off, motors held"
            )
        elif mc.heating() and now >= self.lease_until:
            self._report(mc.stop(T, ErrorCode.HEATER_LEASE, keep_motors=True, value=self.lease_ms))
            self._notice(
                f"heater lease of {self.lease_ms} ms not renewed by the host: heaters off, "
                f"motion stopped after segment {mc.segments_done}, motors held"
            )

    # ------------------------------------------------------------------ protocol handlers

    def _announce_boot(self, now: float) -> None:
        self._boot_sent = now
        self.endpoint.send_urgent(encode_message(self._boot_message()))

    def _report(self, reports: list[Message]) -> None:
        """One DATA frame per report; a HEALTH rides with the STATUS before it."""
        if not self.synced:
            return
        payloads: list[bytes] = []
        for r in reports:
            if isinstance(r, Health) and payloads:
                payloads[-1] += encode_message(r)
            else:
                payloads.append(encode_message(r))
        for payload in payloads:
            if len(self.endpoint.sender.backlog) < MAX_REPORT_BACKLOG:
                self.endpoint.send(payload)
            else:
                self.reports_dropped += 1

    def _urgent(self, payload: bytes, now: float) -> None:
        try:
            msgs = decode_messages(payload, SegmentContext())
        except MessageError:
            return
        if len(msgs) != 1:
            return
        msg = msgs[0]
        if isinstance(msg, Hello):
            if not self.synced:
                # the first session's IDENT comes after a whole BOOT: a host whose flush at
                # its open cut an announcement short still hears what this boot kept
                self._announce_boot(now)
            if msg.major == PROTOCOL_MAJOR and (not self.synced or msg.nonce != self.nonce):
                self.endpoint.reset_session()
                self.ctx = SegmentContext(cycles_per_tick=self.config.cycles_per_tick)
                self.synced = True
                self.nonce = msg.nonce
                self.session_minor = min(msg.minor, PROTOCOL_MINOR)
                self._open_session_state(now)
            self.endpoint.send_urgent(encode_message(self.ident(msg.nonce)))
        elif isinstance(msg, EmergencyStop):
            mc = self.machine
            if not mc.estopped:
                self._report(
                    mc.stop(
                        self.device_time(now),
                        ErrorCode.ESTOP,
                        keep_heaters=bool(msg.flags & EstopFlag.KEEP_HEATERS),
                        keep_motors=not msg.flags & EstopFlag.RELEASE_MOTORS,
                    )
                )
                mc.estopped = True
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
        except MessageError as exc:
            self._report(
                [
                    mc.fail(
                        ErrorCode.BAD_COMMAND,
                        mc.items_received,
                        mc.segments_received,
                        T,
                        exc.opcode,
                        exc.offset,
                    )
                ]
            )
            return True
        queued = 0
        for x in msgs:
            if x.QUEUED:
                queued += 1
            elif x.CLASS in {"U", "D"}:  # URGENT-only or device messages in DATA
                self._report([mc.fail(ErrorCode.BAD_COMMAND, mc.items_received, 0, T, x.OPCODE, 0)])
                return True
        if queued > mc.free_slots() and not mc.fault:
            mc.overflow_rejects += 1
            return False
        ring = self._session_ring() if not mc.fault else None
        if ring is not None and not ring.takes(block_needs(msgs)):
            ring.rejects += 1  # (its blocks would wait for room: refused, sent again)
            return False
        self.ctx = work
        reports: list[Message] = []
        for msg in msgs:
            if msg.QUEUED:
                reports += self._enqueue(msg, T)
            else:
                reports += self._immediate(msg, T)
        self._report(reports)
        return True

    def _immediate(self, msg: Message, T: float) -> list[Message]:
        mc = self.machine
        if isinstance(msg, GetStatus):
            return (
                [self.status(), self.health()]
                if self.session_minor >= MINOR_SAFETY
                else [self.status()]
            )
        if isinstance(msg, Identify):
            return [self.ident(0)]
        if isinstance(msg, GetCaps):
            after: list[Message] = (
                [Stepping(self.config.profile_rate)] if self.session_minor >= MINOR_STEPPING else []
            )
            if self.session_minor >= MINOR_BUDGET and self.config.total_step_rate:
                after.append(StepBudget(self.config.total_step_rate))
            return [self.caps(), *after]
        if isinstance(msg, ClearFault):
            if mc.latched:  # a thermal fault: only a reset clears it
                return [Event(EventCode.CLEAR_REFUSED, mc.items_done, (mc.latched,))]
            if mc.clear_fault():
                return [Event(EventCode.FAULT_CLEARED, mc.items_done, ())]
        elif isinstance(msg, Flush):
            mc.flush(T)
        elif isinstance(msg, Configure):
            self.watchdog_ms = msg.watchdog_ms
            mc.start_ticks = msg.start_ticks
            self.flow.flow_ticks = msg.flow_ticks
        elif isinstance(msg, HeaterLease):
            self.lease_ms = msg.ms
            self.lease_until = self._now + msg.ms / 1000.0
        elif isinstance(msg, SetLimits):
            if msg.lo > msg.hi:
                return self._bad_value(0, msg.OPCODE, msg.module, T)
            mc.limits.set(msg.module, msg.lo, msg.hi)
        elif isinstance(msg, SetPid):
            if msg.heater >= HEATERS:
                return self._bad_value(0, msg.OPCODE, msg.heater, T)
            mc.heaters[msg.heater].set_gains(PidGains.from_wire(msg.kp, msg.ki, msg.kd))
        return []

    def _bad_value(self, n: int, opcode: int, value: int, T: float) -> list[Message]:
        return [self.machine.fail(ErrorCode.BAD_VALUE, n, 0, T, opcode, value)]

    def _enqueue(self, msg: Message, T: float) -> list[Message]:
        """Number one queue item, check its device-dependent ranges, queue it."""
        mc = self.machine
        mc.items_received += 1
        n = mc.items_received
        seg = mc.segments_received + 1 if isinstance(msg, Segment) else 0
        cfg = self.config
        item = item_of(msg, n, T, seg, cfg.clock_hz, HEATERS, cfg.fans, cfg.min_segment_ticks)
        mc.segments_received += seg > 0  # a refused segment keeps its number too
        if isinstance(item, BadValue):
            return self._bad_value(n, msg.OPCODE, item.value, T)
        if isinstance(msg, Segment) and not mc.fault:
            refused = schedule_refusal(
                msg.ticks,
                msg.deltas,
                msg.ramp,
                dict(msg.schedules),
                cycles_per_tick=cfg.cycles_per_tick,
                tol_cycles=cfg.schedule_tolerance_cycles,
                min_interval_cycles=cfg.min_step_interval_cycles,
                table=self.ctx.table,
            )
            if refused is not None:  # before any of it moves
                return [mc.fail(ErrorCode.BAD_VALUE, n, seg, T, *refused)]
            ring = self._session_ring()
            if ring is not None and msg.schedules:
                ring.put(seg, block_needs([msg])[0])
        reports = mc.enqueue(item, T)
        self._session_ring()  # (its start rule after this block)
        return reports

    def close(self) -> None:
        """Flush and close the streamed record."""
        self.record.close()


__all__ = ["ErrorReport", "SimDevice"]
