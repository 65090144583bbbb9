"""HostLink: the host end of the link to the printer's firmware (or its simulation).

Cooperative and thread-safe: every public call "pumps" the link (writes due frames,
reads what arrived, acknowledges, retransmits) under a lock, waiting in the
transport (``select`` on a port) so it wakes on the device's reports rather than on a
timer. On a real port a keep-alive thread pumps when nobody else has for a quarter
of the device's watchdog, so an idle or paused host keeps its session (PROTOCOL.md
3.3) and a stopped or killed one trips it. Fatal conditions (device reset, device
fault, silence, port gone) are raised by whichever call notices them and stay raised
by every later call.

Motion is streamed with :meth:`HostLink.feed`: it sends as much of a batch as the
device's free slots and the time watermarks allow (PROTOCOL.md section 6) and waits
for room at most ``max_wait`` seconds.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, Protocol

from cdprhost.link.errors import (
    DeviceFault,
    DeviceReset,
    DeviceSilent,
    LinkError,
    LinkTimeout,
)
from cdprhost.link.events import DeviceProgress, DeviceStatus, Identity, LinkCounters, LinkEvent
from cdprhost.link.flow import TimeFlow, Watermarks
from cdprhost.link.segment_feed import SegmentFeed
from cdprhost.link.session_setup import SessionSetup
from cdprhost.link.tracker import DeviceTracker
from cdprhost.link.tuning import (
    MAX_WINDOW,
    MIN_PAYLOAD,
    MIN_WINDOW,
    RTO_FLOOR_S,
    RTO_MAX_BACKOFF,
    SLICE_S,
    START_WINDOW,
    STATUS_TIMEOUTS,
)
from firmware_protocol.endpoint import Endpoint
from firmware_protocol.framing import MAX_PAYLOAD, Kind, encode_frame
from firmware_protocol.message_codec import encode_message, encode_messages
from firmware_protocol.messages import (
    WATCHDOG_MS_DEFAULT,
    WATCHDOG_MS_RANGE,
    ClearFault,
    EmergencyStop,
    ErrorCode,
    Flag,
    GetStatus,
    Message,
    Segment,
)
from firmware_protocol.segments import (
    SegmentContext,
)

log = logging.getLogger(__name__)


class Transport(Protocol):
    name: str

    def now(self) -> float: ...
    def write(self, data: bytes) -> None: ...
    def read(self, timeout: float) -> bytes: ...
    def close(self) -> None: ...


class HostLink(SessionSetup, SegmentFeed):
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
    ):
        self._t = transport
        self.timeout_s = float(timeout_s)
        self.device = device  # the SimDevice when embedded, else None
        self.watermarks = watermarks or Watermarks()
        lo, hi = WATCHDOG_MS_RANGE
        self.watchdog_ms = max(lo, min(hi, int(watchdog_ms)))
        self._lock = threading.RLock()
        self._waiters = 0
        self._max_window = max(1, min(MAX_WINDOW, window))
        self._ep = Endpoint(
            window=min(START_WINDOW, self._max_window),
            rto_initial=min(0.05, self.timeout_s / 4),
            rto_floor=RTO_FLOOR_S,
            rto_max_backoff=RTO_MAX_BACKOFF,
            rto_ceiling=min(0.25, self.timeout_s / 4),
            byte_time=10.0 / baud if baud else 0.0,
        )
        self._ctx = SegmentContext()
        self._max_payload: int = max_payload
        self._payload_limit = max_payload
        self._dev: DeviceTracker = DeviceTracker(getattr(transport, "name", "port"))
        self._flow: TimeFlow = TimeFlow(self.watermarks)
        self._items_sent = 0
        self._segments_sent = 0
        now = transport.now()
        self._last_rx = now
        self._last_tx = now
        self._last_pump = now
        self._waiting_since: float | None = None
        self._garbage_since_valid = 0
        self._last_retx = 0
        self._acked_clean = 0
        self._configured_rate = 0.0
        self._start_ticks = 0
        self._ka_stop: threading.Event | None = None
        self._ka_thread: threading.Thread | None = None

    # ------------------------------------------------------------------ locking

    @contextmanager
    def _locked(self) -> Iterator[None]:
        self._waiters += 1
        self._lock.acquire()
        self._waiters -= 1
        try:
            yield
        finally:
            self._lock.release()

    def _let_others_in(self) -> None:
        """Between pump slices, let a thread that waits for the lock have its turn."""
        if self._waiters:
            time.sleep(0.0005)

    # ------------------------------------------------------------------ properties

    @property
    def identity(self) -> Identity | None:
        return self._dev.identity

    def _identity(self) -> Identity:
        identity = self._dev.identity
        if identity is None:
            raise LinkError(f"{self._t.name}: no session (handshake first)")
        return identity

    @property
    def progress(self) -> DeviceProgress:
        return self._dev.progress

    def status(self) -> DeviceStatus | None:
        """The latest status report received (no I/O)."""
        return self._dev.status

    @property
    def items_sent(self) -> int:
        return self._items_sent

    @property
    def segments_sent(self) -> int:
        return self._segments_sent

    @property
    def clock_rate(self) -> float:
        """Device clock ticks per host second, as measured (PROTOCOL.md 3.2)."""
        return self._dev.clock.rate()

    @property
    def counters(self) -> LinkCounters:
        ep = self._ep
        c = ep.counters
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
        )

    def now(self) -> float:
        return self._t.now()

    def _urgent_frame(self, msg: Message) -> bytes:
        return encode_frame(Kind.URGENT, 0, self._ep.receiver.expected, encode_message(msg))

    def _write(self, frames: list[bytes]) -> None:
        for f in frames:  # one write per frame: a wire's faults (duplication) act per frame
            self._t.write(f)
        if frames:
            self._last_tx = self._t.now()

    def _read(self, timeout: float) -> bytes:
        return self._t.read(timeout)

    def _keepalive_due(self, now: float) -> bool:
        interval = min(self.watchdog_ms / 4000.0, self.timeout_s / 4)
        return now - self._last_tx > interval or now - self._last_rx > self.timeout_s / 4

    def _pump(self, max_wait: float = SLICE_S) -> None:
        """One slice: write, wait for bytes (at most ``max_wait``), handle, check liveness."""
        if self._dev.failure is not None:
            raise self._dev.failure
        ep = self._ep
        now = self._t.now()
        self._last_pump = now
        if not ep.sender.idle() and self._waiting_since is None:
            self._waiting_since = now
        self._write(ep.flush(now))
        deadline = ep.next_deadline()
        wait = max_wait if deadline is None else min(max_wait, max(0.0, deadline - now))
        data = self._read(wait)
        now = self._t.now()
        if data:
            before = ep.deframer.frames
            for inc in ep.feed(data, now):
                self._dev.handle(inc, now)
            if ep.deframer.frames > before:
                self._last_rx = now
                self._garbage_since_valid = 0
                self._waiting_since = None if ep.sender.idle() else now
            else:
                self._garbage_since_valid += len(data)
        self._adapt()
        if self._keepalive_due(now) and ep.sender.idle():
            ep.send(encode_message(GetStatus()))
            if self._waiting_since is None:
                self._waiting_since = now
        self._write(ep.flush(now))
        if self._dev.failure is not None:
            raise self._dev.failure
        if (
            self._waiting_since is not None
            and now - self._waiting_since > self.timeout_s
            and now - self._last_rx > self.timeout_s
        ):
            log.warning("%s: device silent for %.1f s", self._t.name, now - self._last_rx)
            self._dev.failure = self._silent_error(self._garbage_since_valid, "")
            raise self._dev.failure

    def _adapt(self) -> None:
        """On a retransmission: shorter frames, half the window; every frame acknowledged
        without one grows them back (2 bytes, 1 frame): a noisy line settles on short frames
        that get through, a clean one on full ones. A frame once sent keeps its size (its
        retransmissions are byte-identical), so frames start small and grow."""
        ep = self._ep
        retx = ep.retransmits
        sender = ep.sender
        clean, self._acked_clean = sender.acked_clean - self._acked_clean, sender.acked_clean
        if retx > self._last_retx:
            self._payload_limit = max(MIN_PAYLOAD, int(self._payload_limit * 0.7))
            sender.window = max(MIN_WINDOW, sender.window // 2)
            log.debug(
                "%s: %d retransmissions; payload %d, window %d",
                self._t.name,
                retx - self._last_retx,
                self._payload_limit,
                sender.window,
            )
        elif clean:
            self._payload_limit = min(self._max_payload, self._payload_limit + 2 * clean)
            sender.window = min(self._max_window, sender.window + clean)
        self._last_retx = retx

    def _wait(self, done: Callable[[], bool], timeout: float | None, what: str) -> None:
        start = self._t.now()
        while True:
            self._let_others_in()
            with self._locked():
                if done():
                    return
                if timeout is not None and self._t.now() - start > timeout:
                    raise LinkTimeout(
                        f"{self._t.name}: {what} did not happen within {timeout:g} s "
                        f"(executed {self.progress.items_done} of {self._items_sent} items)"
                    )
                self._pump()

    # ------------------------------------------------------------------ keep-alive

    def start_keepalive(self) -> None:
        """Pump from a background thread whenever nobody else has for a while (real ports)."""
        if self._ka_thread is not None:
            return
        self._ka_stop = threading.Event()
        self._ka_thread = threading.Thread(
            target=self._keepalive_loop, name="link-keepalive", daemon=True
        )
        self._ka_thread.start()

    def _keepalive_loop(self) -> None:
        stop = self._ka_stop
        assert stop is not None
        interval = min(self.watchdog_ms / 4000.0, self.timeout_s / 4)
        while not stop.wait(interval / 2):
            if self._dev.failure is not None or self._t.now() - self._last_pump < interval / 2:
                continue
            try:
                with self._locked():
                    self._pump(0.0)
            except (LinkError, OSError):
                continue

    def send(self, *commands: Message, timeout: float | None = None) -> list[int]:
        """Send commands in order; returns the item number of each queued one (0 for immediate ones)."""
        self._identity()
        numbers: list[int] = []
        start = self._t.now()
        for cmd in commands:
            is_segment = isinstance(cmd, Segment)
            payload = b"" if is_segment else encode_message(cmd)
            items = 1 if cmd.QUEUED else 0
            while True:
                self._let_others_in()
                with self._locked():
                    if self._dev.failure is not None and not isinstance(
                        cmd, (ClearFault, GetStatus)
                    ):
                        raise self._dev.failure
                    if self._ep.sender.window_free > 0 and self._credit() >= items:
                        ticks = 0
                        if is_segment:  # encoded only now: the coder context follows send order
                            assert isinstance(cmd, Segment)
                            payload = encode_messages([cmd], self._ctx)
                            self._segments_sent += 1
                            ticks = cmd.ticks
                        self._ep.send(payload, items=items, ticks=ticks)
                        if items:
                            self._items_sent += 1
                        numbers.append(self._items_sent if items else 0)
                        self._write(self._ep.flush(self._t.now()))
                        break
                    if timeout is not None and self._t.now() - start > timeout:
                        raise LinkTimeout(
                            f"{self._t.name}: could not send {type(cmd).__name__} within {timeout:g} s"
                        )
                    self._pump()
        return numbers

    # ------------------------------------------------------------------ waiting and queries

    def poll(self, timeout: float = 0.0) -> list[LinkEvent]:
        """Pump for up to ``timeout`` seconds (at least once); return the events since the last
        poll."""
        end = self._t.now() + timeout
        while True:
            self._let_others_in()
            with self._locked():
                self._pump(min(SLICE_S * 5, max(0.0, end - self._t.now())))
                if self._t.now() >= end - 1e-9:
                    break
        with self._locked():
            return self._dev.take_events()

    def wait_report(self, timeout: float) -> None:
        """Pump until a flow report, a status or an error arrives, or ``timeout`` s."""
        flows, statuses = self._dev.flows, self._dev.status_count
        end = self._t.now() + timeout
        while self._dev.flows == flows and self._dev.status_count == statuses:
            left = end - self._t.now()
            if left <= 0:
                return
            self._let_others_in()
            with self._locked():
                self._pump(min(left, 0.25))

    def ask_status(self) -> int:
        """Ask for a status report without waiting for it; returns the count of reports so
        far (:meth:`status` is newer once :attr:`status_count` exceeds it)."""
        count = self._dev.status_count
        self.send(GetStatus())
        return count

    @property
    def status_count(self) -> int:
        return self._dev.status_count

    def request_status(self, timeout: float | None = None) -> DeviceStatus:
        """Ask for a status report and wait for it (default: a few link timeouts, since on
        a lossy line a reply may need several retransmissions)."""
        count = self.ask_status()
        limit = timeout if timeout is not None else STATUS_TIMEOUTS * self.timeout_s
        self._wait(lambda: self._dev.status_count > count, limit, "a status report")
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
            and p.items_done >= self._items_sent
            and self._ep.sender.idle()
            and not p.flags & Flag.MOVING
            and p.queue_free >= identity.queue_capacity
        )

    def wait_idle(self, timeout: float | None = None) -> DeviceProgress:
        """FLUSH, then wait until everything queued has executed and motion has stopped."""
        self.flush()
        self._wait(self.idle, timeout, "the end of motion")
        return self.progress

    def emergency_stop(self, timeout: float = 1.0, flags: int = 0) -> bool:
        """Stop now, bypassing the queue (URGENT frames, repeated until acknowledged);
        ``flags`` (EstopFlag) keep the heaters or motors on."""
        dev = self._dev
        dev.estop_acked = False
        start = self._t.now()
        with self._locked():
            frame = self._urgent_frame(EmergencyStop(flags))
            log.warning("%s: emergency stop (flags %d)", self._t.name, flags)
            while not dev.estop_acked and self._t.now() - start <= timeout:
                self._write([frame])
                failure, dev.failure = dev.failure, None
                try:
                    for _ in range(3):
                        if dev.estop_acked:
                            break
                        self._pump(SLICE_S)
                except LinkError:
                    pass
                finally:
                    dev.failure = dev.failure or failure
            if dev.estop_acked and not isinstance(dev.failure, (DeviceReset, DeviceSilent)):
                p = dev.progress
                dev.failure = DeviceFault(
                    f"{self._t.name}: emergency stop",
                    code=ErrorCode.ESTOP,
                    item=p.items_done,
                    segment=p.segments_done,
                    axis=0xFF,
                    value=0,
                )
            return dev.estop_acked

    def clear_fault(self, timeout: float | None = None) -> None:
        """Leave the device's fault state (after a DeviceFault or an emergency stop)."""
        dev = self._dev
        with self._locked():
            if isinstance(dev.failure, (DeviceReset, DeviceSilent)):
                raise dev.failure
            dev.failure = None
            dev.cleared = False
            dev.clearing = True
        try:
            self.send(ClearFault())
            self._wait(lambda: dev.cleared, timeout or self.timeout_s, "fault clearing")
        finally:
            dev.clearing = False
        with self._locked():
            dev.failure = None
            self._items_sent = max(self._items_sent, dev.progress.items_done)

    def close(self) -> None:
        if self._ka_stop is not None:
            self._ka_stop.set()
        if self._ka_thread is not None:
            self._ka_thread.join(timeout=2.0)
            self._ka_thread = None
        with self._locked():
            self._t.close()

    def __enter__(self) -> HostLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
