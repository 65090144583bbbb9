"""HostLink: the host end of the link to the printer's firmware (or its simulation).

Cooperative and thread-safe: every public call "pumps" the link (writes due frames,
reads what arrived, acknowledges, retransmits) under a lock, waiting in the
transport (``select`` on a port) so it wakes on the device's reports rather than on a
timer. On a real port a keep-alive thread pumps when nobody else has for a quarter
of the device's watchdog, so an idle or paused host keeps its session (PROTOCOL.md
3.3) and a stopped or killed one trips it. Fatal conditions (device reset, device
fault, silence, port gone) are raised by whichever call notices them and stay raised
by every later call.

The link is made of parts: a :class:`~cdprhost.link.core.LinkCore` (transport,
endpoint, device tracker, pumping), the :class:`~cdprhost.link.session_setup.SessionSetup`
and the :class:`~cdprhost.link.segment_feed.SegmentFeed`, each working on the core.

**Heater lease** (2.1 devices): the calls of the code that drives the machine (this
class's public methods) renew the device's heater lease; the keep-alive thread never
does, so a wedged job whose keep-alive still runs loses its heaters within the lease.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from cdprhost.link.collector import quiet_collection
from cdprhost.link.core import LinkCore, Transport
from cdprhost.link.device_setup import DeviceSetup
from cdprhost.link.errors import DeviceFault, DeviceReset, DeviceSilent, LinkError, LinkTimeout
from cdprhost.link.events import (
    DeviceCaps,
    DeviceHealth,
    DeviceProgress,
    DeviceStatus,
    Identity,
    LinkCounters,
    LinkEvent,
    error_name,
)
from cdprhost.link.flow import Watermarks
from cdprhost.link.keepalive import KeepAlive
from cdprhost.link.ring_room import RingReport
from cdprhost.link.segment_feed import SegmentFeed
from cdprhost.link.session_setup import SessionSetup
from cdprhost.link.tuning import (
    HANDSHAKE_S,
    HEATER_LEASE_S,
    MAX_WINDOW,
    SLICE_S,
    STATUS_TIMEOUTS,
)
from firmware_protocol.framing import MAX_PAYLOAD
from firmware_protocol.message_codec import encode_message, encode_messages
from firmware_protocol.messages import (
    MINOR_SAFETY,
    WATCHDOG_MS_DEFAULT,
    WATCHDOG_MS_RANGE,
    Boot,
    ClearFault,
    EmergencyStop,
    ErrorCode,
    Flag,
    Flush,
    GetStatus,
    HeaterLease,
    Message,
    Segment,
    SetHeater,
)
from firmware_protocol.segments import SegmentBatch

log = logging.getLogger(__name__)

__all__ = ["HostLink", "Transport"]


class HostLink:
    """See the package docstring (:mod:`cdprhost.link`) for the API summary."""

    def __init__(
        self,
        transport: Transport,
        *,
        timeout_s: float = 2.0,
        window: int = MAX_WINDOW,
        max_payload: int = MAX_PAYLOAD,
        baud: int | None = 250_000,
        device: Any = None,
        watermarks: Watermarks | None = None,
        watchdog_ms: int = WATCHDOG_MS_DEFAULT,
        heater_lease_s: float = HEATER_LEASE_S,
        handshake_s: float = HANDSHAKE_S,
    ):
        lo, hi = WATCHDOG_MS_RANGE
        self.device = device  # the SimDevice when embedded, else None
        self._core = LinkCore(
            transport,
            timeout_s=timeout_s,
            window=window,
            max_payload=max_payload,
            baud=baud,
            watermarks=watermarks,
            watchdog_ms=max(lo, min(hi, int(watchdog_ms))),
        )
        self._session = SessionSetup(self._core)
        if not handshake_s > 0:  # NaN included
            raise ValueError(f"handshake_s must be a positive number of seconds, not {handshake_s}")
        self._session.limit_s = max(self._core.timeout_s, float(handshake_s))
        self._feed = SegmentFeed(self._core, self._session, self._renew_lease)
        self._t = transport
        self._dev = self._core.dev
        self.lease_ms = max(lo, min(hi, round(heater_lease_s * 1000)))
        self._lease_sent = -1e9
        # heater -> the last target (°C) this host sent over this link: a target found on the
        # device is "from an earlier session" only when it is not one of these
        self.heaters_set: dict[int, float] = {}
        self._keepalive = KeepAlive(self._core, getattr(transport, "wait_readable", None))

    # ------------------------------------------------------------------ properties

    @property
    def timeout_s(self) -> float:
        return self._core.timeout_s

    @property
    def watchdog_ms(self) -> int:
        return self._core.watchdog_ms

    @property
    def watermarks(self) -> Watermarks:
        return self._core.watermarks

    @property
    def identity(self) -> Identity | None:
        return self._dev.identity

    def _identity(self) -> Identity:
        identity = self._dev.identity
        if identity is None:
            raise LinkError(f"{self._core.name}: no session (handshake first)")
        return identity

    @property
    def boot(self) -> Boot | None:
        """The device's BOOT heard before this session (its reset cause and the counters it
        kept through the reset), or None: no reset since its last session."""
        return self._session.boot

    @property
    def caps(self) -> DeviceCaps | None:
        """What a 2.1 device announced (None: a 2.0 device)."""
        return self._dev.caps

    @property
    def ring(self) -> RingReport | None:
        """The device's ring of schedule blocks as it last reported it (3.2: RING; None:
        it keeps none)."""
        return self._dev.ring

    @property
    def health(self) -> DeviceHealth | None:
        """The device's latest timing and receive figures (None: none yet, or a 2.0 device)."""
        return self._dev.health

    @property
    def tuned_gains(self) -> dict[int, tuple[int, ...]]:
        """Heater -> (kp, ki, kd) in thousandths from the device's last AUTOTUNE_DONE."""
        return dict(self._dev.tuned)

    @property
    def progress(self) -> DeviceProgress:
        return self._dev.progress

    @property
    def fault(self) -> DeviceFault | None:
        """The fault the device stopped on in this session (an e-stop, a device error) while
        the link itself works; None when it runs or the link is lost (:attr:`lost`)."""
        failure = self._dev.failure
        return failure if isinstance(failure, DeviceFault) else None

    @property
    def lost(self) -> LinkError | None:
        """What ended the session (a reset, a silent device, the port gone); None while the
        device answers, stopped by a fault or not."""
        return self._core.fatal()

    @property
    def state(self) -> str:
        """What the link is: "connected" (the device answers and runs), "faulted" (it answers
        and is stopped by a fault: :attr:`fault`), "lost" (:attr:`lost`) or "no session"."""
        if self._core.fatal() is not None:
            return "lost"
        if self._dev.identity is None:
            return "no session"
        if self.fault is not None or self._dev.progress.fault:
            return "faulted"
        return "connected"

    def status(self) -> DeviceStatus | None:
        """The latest status report received (no I/O)."""
        return self._dev.status

    @property
    def items_sent(self) -> int:
        return self._core.items_sent

    @property
    def segments_sent(self) -> int:
        return self._core.segments_sent

    @property
    def clock_rate(self) -> float:
        """Device ticks per host second, as measured (PROTOCOL.md 3.2)."""
        return self._core.clock_rate()

    @property
    def counters(self) -> LinkCounters:
        ep = self._core.ep
        c = ep.counters
        h = self._dev.health or DeviceHealth()
        return LinkCounters(
            ep.retransmits,
            ep.sender.timeouts,
            c.naks_received,
            c.naks_sent,
            ep.bad_frames,
            c.frames_sent,
            c.frames_received,
            c.bytes_sent,
            c.bytes_received,
            c.duplicates,
            h.late_pulses,
            h.late_worst_us,
            h.rx_overruns,
            self._feed.ring.held,
            self._feed.ring.disagreements,
            host_late_worst_s=round(self._core.flow.late_worst_s, 4),
            lead_low_max_s=round(self._core.flow.low_max_s, 4),
        )

    def now(self) -> float:
        return self._t.now()

    # ------------------------------------------------------------------ session

    def handshake(self) -> Identity:
        """A new session (e.g. after DeviceReset); numbering continues from the device's
        counters. Sends the machine set-up (:meth:`set_machine`) to a 2.1 device."""
        identity = self._session.handshake()
        self._lease_sent = -1e9
        self._renew_lease()
        return identity

    def recover(self) -> str | None:
        """After the device went silent (frozen, its cable out and back in) and the session
        was declared lost: try a new session on the same port. Returns what happened, in
        words, once the device answers again (the link works again, the device faulted or
        not: its watchdog may have stopped it meanwhile, :attr:`fault` and its status say
        so); None while it stays silent (the failure stays). Other losses (a reset, the port
        gone) are left to a new connect."""
        core = self._core
        lost = core.fatal()
        if not isinstance(lost, DeviceSilent):
            return None
        try:
            self.handshake()
            faulted = self.request_status().faulted
        except (LinkError, OSError) as exc:
            with core.locked():
                if core.fatal() is None:
                    self._dev.failure = lost
            log.debug("%s: still no answer: %s", core.name, exc)
            return None
        state = "stopped by a fault (M999 clears it)" if faulted else "ready"
        log.warning("%s: the device answers again: new session, %s", core.name, state)
        return f"link back: {core.name} answers again (new session; the device is {state})"

    def configure(self) -> None:
        self._session.configure()

    def set_machine(self, setup: DeviceSetup) -> None:
        """The travel limits and heater gains to send at every connect, sent now as well."""
        if setup == self._session.setup:
            return
        self._session.setup = setup
        if self._dev.identity is not None:
            self._session.send_setup()

    def _renew_lease(self) -> None:
        """From the caller's thread only (never the keep-alive): the heater lease (2.1)."""
        core = self._core
        now = core.t.now()
        if self._session.minor < MINOR_SAFETY or now - self._lease_sent < self.lease_ms / 4000:
            return
        with core.locked():
            self._lease_sent = now
            core.send_immediate(HeaterLease(self.lease_ms))
            core.write(core.ep.flush(now))

    def _pump(self, max_wait: float = SLICE_S, *, fault_ok: bool = False) -> None:
        """A pump from the caller's thread (renews the heater lease); ``fault_ok``: see
        :meth:`LinkCore.pump`."""
        self._renew_lease()
        self._core.pump(max_wait, fault_ok=fault_ok)

    def _wait(self, done: Callable[[], bool], timeout: float | None, what: str) -> None:
        self._core.wait(done, timeout, what, pump=self._pump)

    # ------------------------------------------------------------------ keep-alive

    def start_keepalive(self) -> None:
        """Pump from a background thread whenever nobody else has for a while (real ports)."""
        self._keepalive.start()

    def keepalive_step(self) -> None:
        """One turn of the keep-alive thread (see :mod:`cdprhost.link.keepalive`)."""
        self._keepalive.step()

    # ------------------------------------------------------------------ commands

    def send(self, *commands: Message, timeout: float | None = None) -> list[int]:
        """Send commands in order; returns the item number of each queued one (0 for immediate ones)."""
        self._identity()
        self._renew_lease()
        return self._send_each(commands, timeout, self._pump)

    def _send_each(
        self, commands: tuple[Message, ...], timeout: float | None, pump: Callable[[], None]
    ) -> list[int]:
        """Each command once the window and the device's credit have room, pumping with
        ``pump`` while they have none."""
        core = self._core
        numbers: list[int] = []
        start = self._t.now()
        for cmd in commands:
            is_segment = isinstance(cmd, Segment)
            payload = b"" if is_segment else encode_message(cmd)
            items = 1 if cmd.QUEUED else 0
            while True:
                core.let_others_in()
                with core.locked():
                    if self._dev.failure is not None and not isinstance(
                        cmd, (ClearFault, GetStatus)
                    ):
                        raise self._dev.failure
                    if core.ep.sender.window_free > 0 and core.credit() >= items:
                        ticks = 0
                        if is_segment:  # encoded only now: the coder context follows send order
                            assert isinstance(cmd, Segment)
                            payload = encode_messages([cmd], core.ctx)
                            core.segments_sent += 1
                            ticks = cmd.ticks
                        core.ep.send(payload, items=items, ticks=ticks)
                        if isinstance(cmd, SetHeater):
                            self.heaters_set[cmd.heater] = cmd.target_dc / 10
                        if items:
                            core.items_sent += 1
                        numbers.append(core.items_sent if items else 0)
                        core.write(core.ep.flush(self._t.now()))
                        break
                    if timeout is not None and self._t.now() - start > timeout:
                        raise LinkTimeout(
                            f"{core.name}: could not send {type(cmd).__name__} within {timeout:g} s"
                        )
                    pump()
        return numbers

    def feed(
        self, batch: SegmentBatch, start: int = 0, max_wait: float = 0.0, end: int | None = None
    ) -> int:
        """Send segments ``start..end`` of ``batch`` as far as slots, the time watermarks and
        the window allow, waiting for room at most ``max_wait`` s (waking on reports);
        returns the index after the last segment sent. Their segment numbers continue from
        :attr:`segments_sent`."""
        self._renew_lease()
        return self._feed.feed(batch, self._identity(), start, max_wait, end)

    def check_step_rates(self, batch: SegmentBatch) -> None:
        """Raise :class:`StepRateError` for a segment the device would refuse (step rate,
        shorter than its minimum)."""
        self._feed.check_step_rates(batch, self._identity())

    def ahead_ticks(self) -> float:
        return self._feed.ahead_ticks()

    def queue_segments(self, batch: SegmentBatch, timeout: float | None = None) -> range:
        """Stream move segments (blocking until all are sent); returns their segment numbers
        (as in the device record). Raises :class:`StepRateError` for a segment over the
        device's step-rate limit."""
        first = self.segments_sent + 1
        n = len(batch)
        start = self._t.now()
        i = 0
        with quiet_collection():  # (no full collection of the host's heap mid-stream)
            while i < n:
                left = None if timeout is None else timeout - (self._t.now() - start)
                if left is not None and left <= 0:
                    raise LinkTimeout(
                        f"{self._core.name}: could not queue segments within {timeout:g} s"
                    )
                i = self.feed(batch, i, max_wait=0.25 if left is None else min(0.25, left))
        return range(first, first + n)

    def flush(self) -> None:
        """FLUSH: the motion sent so far may start now (end of a stream, a pause)."""
        self.send(Flush())

    # ------------------------------------------------------------------ waiting and queries

    def poll(self, timeout: float = 0.0, *, fault_ok: bool = False) -> list[LinkEvent]:
        """Pump for up to ``timeout`` seconds (at least once); return the events since the last
        poll. A device stopped by a fault raises its :class:`DeviceFault` unless ``fault_ok``
        (a screen that watches it: its temperatures still come)."""
        core = self._core
        end = self._t.now() + timeout
        while True:
            core.let_others_in()
            with core.locked():
                self._pump(min(SLICE_S * 5, max(0.0, end - self._t.now())), fault_ok=fault_ok)
                if self._t.now() >= end - 1e-9:
                    break
        with core.locked():
            return self._dev.take_events()

    def wait_report(self, timeout: float) -> None:
        """Pump until a flow report, a status or an error arrives, or ``timeout`` s."""
        flows, statuses = self._dev.flows, self._dev.status_count
        end = self._t.now() + timeout
        while self._dev.flows == flows and self._dev.status_count == statuses:
            left = end - self._t.now()
            if left <= 0:
                return
            self._core.let_others_in()
            with self._core.locked():
                self._pump(min(left, 0.25))

    def ask_status(self) -> int:
        """Ask for a status report without waiting for it; returns the count of reports so
        far (:meth:`status` is newer once :attr:`status_count` exceeds it). Asking is not
        driving: it does not renew the heater lease, so a thread that only watches (a screen
        refreshing temperatures) cannot keep a wedged job's heaters on."""
        count = self._dev.status_count
        self._identity()
        fatal = self._core.fatal()
        if fatal is not None:
            raise fatal
        # a pump that renews nothing; a device stopped by a fault answers too
        self._send_each((GetStatus(),), None, lambda: self._core.pump(fault_ok=True))
        return count

    @property
    def status_count(self) -> int:
        return self._dev.status_count

    def request_status(self, timeout: float | None = None) -> DeviceStatus:
        """Ask for a status report and wait for it (default: a few link timeouts, since on
        a lossy line a reply may need several retransmissions). A device stopped by a fault
        answers (its :attr:`fault` says which); a lost link raises."""
        count = self.ask_status()
        limit = timeout if timeout is not None else STATUS_TIMEOUTS * self.timeout_s
        self._core.wait(
            lambda: self._dev.status_count > count,
            limit,
            "a status report",
            pump=lambda: self._pump(fault_ok=True),
        )
        st = self._dev.status
        assert st is not None
        return st

    def wait_items(self, item: int, timeout: float | None = None) -> DeviceProgress:
        """Until the device has executed queue item ``item``."""
        self._wait(lambda: self.progress.items_done >= item, timeout, f"execution of item {item}")
        return self.progress

    def idle(self) -> bool:
        """Everything queued has executed and motion has stopped (no I/O)."""
        p = self.progress
        identity = self._dev.identity
        return (
            identity is not None
            and p.items_done >= self.items_sent
            and self._core.ep.sender.idle()
            and not p.flags & Flag.MOVING
            and p.queue_free >= identity.queue_capacity
        )

    def wait_idle(self, timeout: float | None = None) -> DeviceProgress:
        """FLUSH, then wait until everything queued has executed and motion has stopped.
        A fault that arrives meanwhile is raised, even when the progress that shows the
        queue done (a refused item counts as done) is read before the error report."""
        faulted_before = self.progress.fault
        self.flush()
        self._wait(self.idle, timeout, "the end of motion")
        if self.progress.fault and not faulted_before:
            self._wait(lambda: False, self.timeout_s, "the device's error report")
        return self.progress

    # ------------------------------------------------------------------ stopping

    def emergency_stop(self, timeout: float = 1.0, flags: int = 0) -> bool:
        """Stop now, bypassing the queue (URGENT frames, repeated until acknowledged);
        ``flags`` (EstopFlag) keep the heaters or motors on."""
        core = self._core
        dev = self._dev
        dev.estop_acked = False
        start = self._t.now()
        with core.locked():
            frame = core.urgent_frame(EmergencyStop(flags))
            log.warning("%s: emergency stop (flags %d)", core.name, flags)
            while not dev.estop_acked and self._t.now() - start <= timeout:
                core.write([frame])
                failure, dev.failure = dev.failure, None
                try:
                    for _ in range(3):
                        if dev.estop_acked:
                            break
                        core.pump(SLICE_S)
                except LinkError:
                    pass
                finally:
                    dev.failure = dev.failure or failure
            if dev.estop_acked and not isinstance(dev.failure, (DeviceReset, DeviceSilent)):
                p = dev.progress
                dev.failure = DeviceFault(
                    f"{core.name}: emergency stop",
                    code=ErrorCode.ESTOP,
                    item=p.items_done,
                    segment=p.segments_done,
                    axis=0xFF,
                    value=0,
                )
            return dev.estop_acked

    def clear_fault(self, timeout: float | None = None) -> None:
        """Leave the device's fault state (after a DeviceFault or an emergency stop). A 2.1
        device refuses to clear a latched thermal fault: DeviceFault naming it."""
        dev = self._dev
        with self._core.locked():
            if isinstance(dev.failure, (DeviceReset, DeviceSilent)):
                raise dev.failure
            dev.failure = None
            dev.cleared = False
            dev.clearing = True
            dev.refused = 0
        try:
            self.send(ClearFault())
            self._wait(
                lambda: dev.cleared or bool(dev.refused),
                timeout or self.timeout_s,
                "fault clearing",
            )
        finally:
            dev.clearing = False
        with self._core.locked():
            if dev.refused:
                name = error_name(dev.refused)
                p = dev.progress
                dev.failure = DeviceFault(
                    f"{self._core.name}: the device refuses to clear {name}: a thermal fault "
                    "stays until the device is reset (check the heater and its sensor first)",
                    code=dev.refused,
                    item=p.items_done,
                    segment=p.segments_done,
                    axis=0xFF,
                    value=0,
                )
                raise dev.failure
            dev.failure = None
            dev.forget_errors()
            self._core.items_sent = max(self._core.items_sent, dev.progress.items_done)

    def close(self) -> None:
        self._keepalive.stop()
        with self._core.locked():
            self._t.close()

    def __enter__(self) -> HostLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
