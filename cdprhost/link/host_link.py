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
import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, Protocol

import numpy as np

from cdprhost.link.errors import (
    DeviceFault,
    DeviceReset,
    DeviceSilent,
    LinkError,
    LinkTimeout,
    ProtocolMismatch,
)
from cdprhost.link.events import DeviceProgress, DeviceStatus, Identity, LinkCounters, LinkEvent
from cdprhost.link.flow import TimeFlow, Watermarks
from cdprhost.link.tracker import DeviceTracker, decode_one
from firmware_protocol.endpoint import Endpoint
from firmware_protocol.framing import MAX_PAYLOAD, Kind, encode_frame
from firmware_protocol.messages import (
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    WATCHDOG_MS_DEFAULT,
    WATCHDOG_MS_RANGE,
    Boot,
    ClearFault,
    Configure,
    EmergencyStop,
    ErrorCode,
    Flag,
    Flush,
    GetStatus,
    Hello,
    Ident,
    Message,
    Segment,
    encode_message,
    encode_messages,
)
from firmware_protocol.segments import (
    SegmentBatch,
    SegmentContext,
    encode_segments,
    peak_step_rates,
)

log = logging.getLogger(__name__)

SLICE_S = 0.02
MIN_PAYLOAD = 24
START_PAYLOAD = 64  # frames start small and grow while the line is clean
MAX_WINDOW = 127
START_WINDOW = 8
MIN_WINDOW = 8
CLOCK_SYNC_S = 0.06  # clock samples this far apart before streaming
STATUS_TIMEOUTS = 3  # a status reply may take this many link timeouts on a lossy line


class Transport(Protocol):
    name: str

    def now(self) -> float: ...
    def write(self, data: bytes) -> None: ...
    def read(self, timeout: float) -> bytes: ...
    def close(self) -> None: ...


class StepRateError(LinkError, ValueError):
    """A segment over the device's announced step rate (the host checks before sending)."""


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
            rto_floor=0.01,
            rto_ceiling=min(0.25, self.timeout_s / 4),
            byte_time=10.0 / baud if baud else 0.0,
        )
        self._ctx = SegmentContext()
        self._max_payload = max_payload
        self._payload_limit = max_payload
        self._dev = DeviceTracker(getattr(transport, "name", "port"))
        self._flow = TimeFlow(self.watermarks)
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

    # ------------------------------------------------------------------ handshake

    def handshake(self) -> Identity:
        """HELLO with a fresh nonce until the device answers IDENT; check the protocol version;
        measure the device clock; configure the watchdog, start threshold and flow reports."""
        with self._locked():
            nonce = int.from_bytes(os.urandom(2), "little") or 1
            self._ep.reset_session()
            self._ep.sender.window = min(START_WINDOW, self._max_window)
            self._last_retx = self._acked_clean = 0
            self._ctx = SegmentContext()
            start = self._t.now()
            resend_at = start
            rx_bytes = 0
            identity = None
            while identity is None:
                now = self._t.now()
                if now - start > self.timeout_s:
                    raise self._silent_error(rx_bytes, "during the handshake")
                if now >= resend_at:
                    self._write([self._urgent_frame(Hello(nonce, PROTOCOL_MAJOR, PROTOCOL_MINOR))])
                    resend_at = now + max(0.05, self.timeout_s / 8)
                data = self._read(min(SLICE_S * 5, max(0.0, resend_at - now)))
                rx_bytes += len(data)
                frames = self._ep.deframer.feed(data)
                for k, fr in enumerate(frames):
                    if fr.kind != Kind.URGENT:
                        continue
                    msg = decode_one(fr.payload)
                    if isinstance(msg, Ident) and msg.nonce == nonce:
                        self._accept_ident(msg)
                        now = self._t.now()
                        for inc in self._ep.process(frames[k + 1 :], now):
                            self._dev.handle(inc, now)
                        identity = self._identity()
                        break
                    if isinstance(msg, Boot) and msg.major != PROTOCOL_MAJOR:
                        self._mismatch(msg.major, msg.minor)
        log.info(
            "%s: session with %s %s (protocol %d.%d, queue %d, clock %d Hz)",
            self._t.name,
            identity.firmware_name,
            identity.firmware_version,
            *identity.protocol,
            identity.queue_capacity,
            identity.clock_hz,
        )
        self._sync_clock()
        self.configure()
        return identity

    def _mismatch(self, major: int, minor: int) -> None:
        raise ProtocolMismatch(
            f"{self._t.name}: device speaks protocol {major}.{minor}, host speaks {PROTOCOL_MAJOR}.{PROTOCOL_MINOR}; "
            "update the firmware or the host so the major versions match",
            device_version=(major, minor),
            host_version=(PROTOCOL_MAJOR, PROTOCOL_MINOR),
        )

    def _accept_ident(self, msg: Ident) -> None:
        if msg.major != PROTOCOL_MAJOR:
            self._mismatch(msg.major, msg.minor)
        self._max_payload = min(self._max_payload, msg.max_payload)
        self._payload_limit = min(self._max_payload, START_PAYLOAD)
        self._ep.sender.window_bytes = msg.rx_window
        now = self._t.now()
        self._dev.accept_ident(msg, now)
        self._items_sent = msg.items_received
        self._segments_sent = msg.segments_received
        self._last_rx = now

    def _sync_clock(self) -> None:
        """Status requests until the device clock's rate is measured (a few tens of ms)."""
        start = self._t.now()
        while not self._dev.clock.known:
            if self._t.now() - start > self.timeout_s:
                raise self._silent_error(0, "while reading the device clock")
            count = self.ask_status()
            self._wait(
                lambda c=count: self._dev.status_count > c,  # type: ignore[misc]
                STATUS_TIMEOUTS * self.timeout_s,
                "a status report",
            )
            if not self._dev.clock.known:
                self.poll(CLOCK_SYNC_S / 3)

    def configure(self) -> None:
        """Send the watchdog, the start threshold (most of the high watermark) and the flow
        interval (half the watermarks' gap), in device ticks at the measured clock rate."""
        rate = self.clock_rate
        marks = self.watermarks
        cap = 0xFFFF_FFFF
        start = min(cap, self._flow.start_ticks(rate))
        flow = min(cap, max(1, round((marks.high_s - marks.low_s) * rate / 2)))
        self._configured_rate = rate
        self._start_ticks = start
        self.send(Configure(self.watchdog_ms, start, flow))
        log.debug("%s: configured start %d ticks, flow %d ticks", self._t.name, start, flow)

    def _silent_error(self, rx_bytes: int, when: str) -> DeviceSilent:
        name = self._t.name
        p = self._dev.progress
        when = f" {when}" if when else ""
        if rx_bytes and self._ep.deframer.frames == 0:
            text = (
                f"{name}: {rx_bytes} bytes but no valid frame{when} within {self.timeout_s:g} s; "
                "wrong baud rate, or not a cdpr device (or one speaking protocol 1)?"
            )
        else:
            text = (
                f"{name}: no answer from the device{when} within {self.timeout_s:g} s "
                f"(last reported executed segment {p.segments_done}); is it powered and connected?"
            )
        return DeviceSilent(text, last_segment=p.segments_done, last_item=p.items_done)

    # ------------------------------------------------------------------ pumping

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

    # ------------------------------------------------------------------ sending

    def _credit(self) -> int:
        flow = self._dev.flow
        return flow.free - self._ep.sender.items_after(flow.ack)

    def ahead_ticks(self) -> float:
        """Device ticks of motion held ahead of the device's now (estimated; see flow.py)."""
        flow = self._dev.flow
        return self._flow.ahead_ticks(
            flow, self._t.now(), self.clock_rate, self._ep.sender.ticks_after(flow.ack)
        )

    def _window_room(self) -> int:
        """Payload bytes the window can still take (sent or queued frames count)."""
        s = self._ep.sender
        if s.window_free <= 0:
            return 0
        cap = s.window_bytes or 1 << 20
        queued = sum(len(o.payload) for o in s.outstanding) + sum(len(b.payload) for b in s.backlog)
        return max(0, cap - queued)

    def _sendable(self, ticks: np.ndarray) -> int:
        """How many of the segments with durations ``ticks`` may go now."""
        slots = self._credit()
        if slots <= 0:
            return 0
        rate = self.clock_rate
        if abs(rate - self._configured_rate) > 0.1 * self._configured_rate:
            self.configure()
        moving = bool(self._dev.flow.flags & Flag.MOVING)
        room = self._flow.room_ticks(self.ahead_ticks(), rate, moving, self._start_ticks)
        if room <= 0:
            return 0
        window = self._window_room()
        if window <= 0:
            return 0
        limit = min(len(ticks), slots, max(8, window // 2))
        cum = np.cumsum(ticks[:limit])
        return min(limit, int(np.searchsorted(cum, room, side="right")) + 1)

    def _send_segments(self, batch: SegmentBatch, i: int, j: int) -> None:
        sub = batch[i:j]
        data, offsets = encode_segments(sub, self._ctx)
        n = j - i
        pos = 0
        limit = self._payload_limit
        ticks = sub.ticks
        while pos < n:
            end = int(np.searchsorted(offsets, offsets[pos] + limit, side="right")) - 1
            end = max(pos + 1, min(end, n))
            self._ep.send(
                data[offsets[pos] : offsets[end]],
                items=end - pos,
                ticks=int(ticks[pos:end].sum()),
            )
            pos = end
        self._items_sent += n
        self._segments_sent += n
        self._write(self._ep.flush(self._t.now()))

    def check_step_rates(self, batch: SegmentBatch) -> None:
        """Raise :class:`StepRateError` for a segment over the device's max step rate."""
        identity = self._identity()
        rates = peak_step_rates(batch, identity.clock_hz)
        over = np.flatnonzero((rates > identity.max_step_rate).any(axis=1))
        if over.size:
            k = int(over[0])
            raise StepRateError(
                f"segment {k} of the batch: peak step rate {rates[k].max():.0f}/s exceeds the device "
                f"limit {identity.max_step_rate}/s"
            )

    def feed(
        self, batch: SegmentBatch, start: int = 0, max_wait: float = 0.0, end: int | None = None
    ) -> int:
        """Send segments ``start..end`` of ``batch`` as far as slots, the time watermarks and
        the window allow, waiting for room at most ``max_wait`` s (waking on reports);
        returns the index after the last segment sent. Their segment numbers continue from
        :attr:`segments_sent`."""
        n = len(batch) if end is None else min(end, len(batch))
        if start >= n:
            return start
        if start == 0:
            self.check_step_rates(batch)
        until = self._t.now() + max_wait
        i = start
        while i < n:
            self._let_others_in()
            with self._locked():
                if self._dev.failure is not None:
                    raise self._dev.failure
                k = self._sendable(batch.ticks[i:n])
                if k > 0:
                    self._send_segments(batch, i, i + k)
                    i += k
                    continue
                now = self._t.now()
                if now >= until:
                    break
                wake = self._flow.wake_in(
                    self.ahead_ticks(), self.clock_rate, bool(self._dev.flow.flags & Flag.MOVING)
                )
                # below the low watermark already: only a report can give room
                wait = until - now if not wake else min(until - now, wake)
                self._pump(min(wait, 0.25))
        return i

    def queue_segments(self, batch: SegmentBatch, timeout: float | None = None) -> range:
        """Stream move segments (blocking until all are sent); returns their segment numbers
        (as in the device record). Raises :class:`StepRateError` for a segment over the
        device's step-rate limit."""
        first = self._segments_sent + 1
        n = len(batch)
        start = self._t.now()
        i = 0
        while i < n:
            left = None if timeout is None else timeout - (self._t.now() - start)
            if left is not None and left <= 0:
                raise LinkTimeout(f"{self._t.name}: could not queue segments within {timeout:g} s")
            i = self.feed(batch, i, max_wait=0.25 if left is None else min(0.25, left))
        return range(first, first + n)

    def flush(self) -> None:
        """FLUSH: the motion sent so far may start now (end of a stream, a pause)."""
        self.send(Flush())

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
