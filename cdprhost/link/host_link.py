"""HostLink: the host end of the link to the printer's firmware (or its simulation).

Cooperative and thread-safe: there is no background thread. Every public call
"pumps" the link (writes due frames, reads what arrived, acknowledges, retransmits)
in short slices under a lock, so another thread (the UI, an emergency stop) can
get in between. Call :meth:`HostLink.poll` now and then while nothing else runs
(every ~0.1 s) so device reports keep flowing. Fatal conditions (device reset,
device fault, silence, port gone) are raised by whichever call notices them and
stay raised by every later call.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from cdprhost.link.errors import (
    DeviceFault,
    DeviceReset,
    DeviceSilent,
    LinkError,
    LinkTimeout,
    ProtocolMismatch,
)
from cdprhost.link.events import DeviceStatus, Identity, LinkCounters, LinkEvent, Progress
from cdprhost.link.tracker import DeviceTracker, decode_one
from firmware_protocol.endpoint import Endpoint
from firmware_protocol.framing import MAX_PAYLOAD, Kind, encode_frame
from firmware_protocol.messages import (
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    Boot,
    ClearFault,
    EmergencyStop,
    ErrorCode,
    Flag,
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

SLICE_S = 0.02
MIN_PAYLOAD = 48


@dataclass
class _Waiting:
    since: float | None = None


class HostLink:
    """See the package docstring (:mod:`cdprhost.link`) for the API summary."""

    def __init__(
        self,
        transport,
        *,
        timeout_s: float = 2.0,
        window: int = 8,
        max_payload: int = MAX_PAYLOAD,
        baud: int | None = 250_000,
        device=None,
    ):
        self._t = transport
        self.timeout_s = float(timeout_s)
        self.device = device  # the SimDevice when embedded, else None
        self._lock = threading.RLock()
        self._waiters = 0
        self._ep = Endpoint(
            window=window,
            rto_initial=min(0.25, self.timeout_s / 4),
            rto_floor=0.01,
            rto_ceiling=min(1.0, self.timeout_s / 2),
            byte_time=10.0 / baud if baud else 0.0,
        )
        self._ctx = SegmentContext()
        self._max_payload = max_payload
        self._payload_limit = max_payload
        self._dev = DeviceTracker(getattr(transport, "name", "port"))
        self._items_sent = 0
        self._segments_sent = 0
        self._last_rx = transport.now()
        self._waiting = _Waiting()
        self._garbage_since_valid = 0
        self._keepalive_at = -1.0
        self._last_retx = 0

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

    @property
    def progress(self) -> Progress:
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
        """HELLO with a fresh nonce until the device answers IDENT; check the protocol version."""
        with self._locked():
            nonce = int.from_bytes(os.urandom(2), "little") or 1
            self._ep.reset_session()
            self._ctx = SegmentContext()
            start = self._t.now()
            resend_at = start
            rx_bytes = 0
            while True:
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
                        return self.identity  # type: ignore[return-value]
                    if isinstance(msg, Boot) and msg.major != PROTOCOL_MAJOR:
                        self._mismatch(msg.major, msg.minor)

    def _mismatch(self, major: int, minor: int):
        raise ProtocolMismatch(
            f"{self._t.name}: device speaks protocol {major}.{minor}, host speaks {PROTOCOL_MAJOR}.{PROTOCOL_MINOR}; "
            "update the firmware or the host so the major versions match",
            device_version=(major, minor),
            host_version=(PROTOCOL_MAJOR, PROTOCOL_MINOR),
        )

    def _accept_ident(self, msg: Ident) -> None:
        if msg.major != PROTOCOL_MAJOR:
            self._mismatch(msg.major, msg.minor)
        self._max_payload = self._payload_limit = min(self._max_payload, msg.max_payload)
        self._dev.accept_ident(msg, self._max_payload)
        self._items_sent = msg.items_received
        self._segments_sent = msg.segments_received
        self._last_rx = self._t.now()

    def _silent_error(self, rx_bytes: int, when: str) -> DeviceSilent:
        name = self._t.name
        p = self._dev.progress
        when = f" {when}" if when else ""
        if rx_bytes and self._ep.deframer.frames == 0:
            text = (
                f"{name}: {rx_bytes} bytes but no valid frame{when} within {self.timeout_s:g} s; "
                "wrong baud rate, or not a cdpr device?"
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
        for f in frames:
            self._t.write(f)

    def _read(self, timeout: float) -> bytes:
        return self._t.read(timeout)

    def _pump(self, max_wait: float = SLICE_S) -> None:
        """One slice: write, wait for bytes (at most ``max_wait``), handle, check liveness."""
        if self._dev.failure is not None:
            raise self._dev.failure
        ep = self._ep
        now = self._t.now()
        if not ep.sender.idle() and self._waiting.since is None:
            self._waiting.since = now
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
                self._waiting.since = None if ep.sender.idle() else now
            else:
                self._garbage_since_valid += len(data)
        self._adapt_payload()
        self._write(ep.flush(now))
        if self._dev.failure is not None:
            raise self._dev.failure
        quiet = now - self._last_rx
        if quiet > self.timeout_s / 4 and now >= self._keepalive_at:
            self._keepalive_at = now + self.timeout_s / 4
            ep.send(encode_message(GetStatus()))
            if self._waiting.since is None:
                self._waiting.since = now
        if (
            self._waiting.since is not None
            and now - self._waiting.since > self.timeout_s
            and quiet > self.timeout_s
        ):
            self._dev.failure = self._silent_error(self._garbage_since_valid, "")
            raise self._dev.failure

    def _adapt_payload(self) -> None:
        retx = self._ep.retransmits
        if retx > self._last_retx:
            self._payload_limit = max(MIN_PAYLOAD, int(self._payload_limit * 0.7))
        elif self._payload_limit < self._max_payload:
            self._payload_limit = min(self._max_payload, self._payload_limit + 2)
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

    # ------------------------------------------------------------------ sending

    def _credit(self) -> int:
        return self._dev.flow_free - self._ep.sender.items_after(self._dev.flow_ack)

    def queue_segments(self, batch: SegmentBatch, timeout: float | None = None) -> range:
        """Stream move segments; returns their segment numbers (as in the device record).

        Blocks (pumping) while the device queue or the window is full; ``timeout``
        bounds the whole call. Raises ValueError for a segment over the step-rate limit.
        """
        if self.identity is None:
            raise LinkError("handshake first")
        n = len(batch)
        if n == 0:
            return range(self._segments_sent + 1, self._segments_sent + 1)
        rates = peak_step_rates(batch, self.identity.clock_hz)
        over = np.flatnonzero((rates > self.identity.max_step_rate).any(axis=1))
        if over.size:
            i = int(over[0])
            raise ValueError(
                f"segment {i} of the batch: peak step rate {rates[i].max():.0f}/s exceeds the device "
                f"limit {self.identity.max_step_rate}/s"
            )
        start = self._t.now()
        with self._locked():
            saved = self._ctx.copy()
            data, offsets = encode_segments(batch, self._ctx)
            first = self._segments_sent + 1
        i = 0
        try:
            while i < n:
                self._let_others_in()
                with self._locked():
                    if self._dev.failure is not None:
                        raise self._dev.failure
                    credit = self._credit()
                    # like Nagle: wait for a worthwhile batch unless the queue is nearly empty
                    worth = min(n - i, max(1, self.identity.queue_capacity // 4))
                    if credit >= worth or (
                        credit > 0 and self._dev.flow_free >= self.identity.queue_capacity // 2
                    ):
                        ok = self._ep.sender.window_free > 0
                    else:
                        ok = False
                    if ok:
                        while i < n and credit > 0 and self._ep.sender.window_free > 0:
                            limit = offsets[i] + self._payload_limit
                            j = int(np.searchsorted(offsets, limit, side="right")) - 1
                            j = max(i + 1, min(j, i + credit, n))
                            self._ep.send(data[offsets[i] : offsets[j]], items=j - i)
                            self._items_sent += j - i
                            self._segments_sent += j - i
                            credit -= j - i
                            i = j
                        self._write(self._ep.flush(self._t.now()))
                        continue
                    if timeout is not None and self._t.now() - start > timeout:
                        raise LinkTimeout(
                            f"{self._t.name}: could not queue segments within {timeout:g} s"
                        )
                    self._pump()
        finally:
            with self._locked():
                if i < n:  # keep the coder in step with what the device will decode
                    self._ctx = (
                        saved
                        if i == 0
                        else SegmentContext(
                            int(batch.ticks[i - 1]), tuple(int(v) for v in batch.deltas[i - 1])
                        )
                    )  # type: ignore[arg-type]
        return range(first, first + n)

    def send(self, *commands: Message, timeout: float | None = None) -> list[int]:
        """Send commands in order; returns the item number of each queued one (0 for immediate ones)."""
        if self.identity is None:
            raise LinkError("handshake first")
        numbers: list[int] = []
        start = self._t.now()
        for cmd in commands:
            is_segment = isinstance(cmd, Segment)
            payload = None if is_segment else encode_message(cmd)
            items = 1 if cmd.QUEUED else 0
            while True:
                self._let_others_in()
                with self._locked():
                    if self._dev.failure is not None and not isinstance(
                        cmd, (ClearFault, GetStatus)
                    ):
                        raise self._dev.failure
                    if self._ep.sender.window_free > 0 and self._credit() >= items:
                        if (
                            is_segment
                        ):  # encoded only now: the coder context must follow the send order
                            payload = encode_messages([cmd], self._ctx)
                            self._segments_sent += 1
                        self._ep.send(payload, items=items)
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
        """Pump for up to ``timeout`` seconds (at least once); return the events since the last poll."""
        end = self._t.now() + timeout
        while True:
            self._let_others_in()
            with self._locked():
                self._pump(min(SLICE_S, max(0.0, end - self._t.now())))
                if self._t.now() >= end - 1e-9:
                    break
        with self._locked():
            return self._dev.take_events()

    def request_status(self, timeout: float | None = None) -> DeviceStatus:
        count = self._dev.status_count
        self.send(GetStatus())
        self._wait(
            lambda: self._dev.status_count > count, timeout or self.timeout_s, "a status report"
        )
        return self._dev.status  # type: ignore[return-value]

    def wait_items(self, item: int, timeout: float | None = None) -> Progress:
        """Until the device has executed queue item ``item``."""
        self._wait(lambda: self.progress.items_done >= item, timeout, f"execution of item {item}")
        return self.progress

    def wait_idle(self, timeout: float | None = None) -> Progress:
        """Until everything queued has executed and motion has stopped."""

        def idle() -> bool:
            p = self.progress
            return (
                p.items_done >= self._items_sent
                and self._ep.sender.idle()
                and not p.flags & Flag.MOVING
                and self.identity is not None
                and p.queue_free >= self.identity.queue_capacity
            )

        self._wait(idle, timeout, "the end of motion")
        return self.progress

    def emergency_stop(self, timeout: float = 1.0) -> bool:
        """Stop now, bypassing the queue (URGENT frames, repeated until acknowledged)."""
        dev = self._dev
        dev.estop_acked = False
        start = self._t.now()
        frame = self._urgent_frame(EmergencyStop())
        with self._locked():
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
        with self._locked():
            self._t.close()

    def __enter__(self) -> HostLink:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
