"""The part of the host link that every other part uses: the transport, the endpoint,
what the host knows of the device, the numbering of what was sent, and pumping.

:class:`LinkCore` is thread-safe through one re-entrant lock (:meth:`locked`). A pump
slice reads what has already arrived *before* it writes retransmissions that fell due,
so an acknowledgement that waited in the port's buffer (a keep-alive thread pumps
rarely) never looks lost. The session set-up (:mod:`.session_setup`), the segment
stream (:mod:`.segment_feed`) and :class:`~cdprhost.link.host_link.HostLink` hold the
one core of a link.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol

from cdprhost.link.errors import DeviceFault, DeviceSilent, LinkError, LinkTimeout
from cdprhost.link.flow import TimeFlow, Watermarks
from cdprhost.link.tracker import DeviceTracker
from cdprhost.link.tuning import (
    CLEAN_DRY_MARGIN_S,
    CLEAN_RTO_FLOOR_MAX_S,
    CLEAN_RTO_FLOOR_S,
    COPY_LOSS,
    FRAME_LOSS_CEILING,
    FRAME_LOSS_SHARE,
    LOSS_MEMORY_BYTES,
    LOSS_PRIOR_BYTES,
    MAX_WINDOW,
    MIN_PAYLOAD,
    MIN_WINDOW,
    RTO_FAST,
    RTO_FLOOR_S,
    RTO_MAX_BACKOFF,
    SLICE_S,
    STALE_REPORT_S,
    START_WINDOW,
)
from firmware_protocol.endpoint import Endpoint
from firmware_protocol.framing import MAX_PAYLOAD, OVERHEAD, Kind, encode_frame
from firmware_protocol.message_codec import encode_message
from firmware_protocol.messages import GetStatus, Message
from firmware_protocol.segments import SegmentContext

log = logging.getLogger("cdprhost.link.host_link")


class Transport(Protocol):
    name: str

    def now(self) -> float: ...
    def write(self, data: bytes) -> None: ...
    def read(self, timeout: float) -> bytes: ...
    def close(self) -> None: ...


class LinkCore:
    """Shared state of one link and its pump (PROTOCOL.md sections 2 and 6)."""

    def __init__(
        self,
        transport: Transport,
        *,
        timeout_s: float,
        window: int = MAX_WINDOW,
        max_payload: int = MAX_PAYLOAD,
        baud: int | None = 250_000,
        watermarks: Watermarks | None = None,
        watchdog_ms: int,
    ):
        self.t = transport
        self.name: str = getattr(transport, "name", "port")
        self.timeout_s = float(timeout_s)
        self.watchdog_ms = watchdog_ms
        self.watermarks = watermarks or Watermarks()
        self._lock = threading.RLock()
        self._waiters = 0
        self.max_window = max(1, min(MAX_WINDOW, window))
        self._ceiling = min(0.25, self.timeout_s / 4)
        # the clean fast path's floor, as learned (at most a quarter of the link timeout)
        self._clean_floor = min(CLEAN_RTO_FLOOR_S, self.timeout_s / 4)
        self._clean_timeouts = 0  # the sender's timeouts seen by the last adaptation
        self.ep = Endpoint(
            window=min(START_WINDOW, self.max_window),
            rto_initial=min(0.05, self.timeout_s / 4),
            rto_floor=RTO_FLOOR_S,
            rto_max_backoff=RTO_MAX_BACKOFF,
            rto_ceiling=self._ceiling,
            byte_time=10.0 / baud if baud else 0.0,
            rto_fast=RTO_FAST,
            stale_after=STALE_REPORT_S,
            renak=True,
        )
        self.ctx = SegmentContext()
        self.max_payload: int = max_payload
        self.payload_limit = max_payload
        self.dev = DeviceTracker(self.name)
        self.flow = TimeFlow(self.watermarks)
        self.items_sent = 0
        self.segments_sent = 0
        now = transport.now()
        self.last_rx = now
        self.last_tx = now
        self.last_pump = now
        self._read_end = now
        self.sent_after = now
        self._waiting_since: float | None = None
        self.garbage_since_valid = 0
        self._last_retx = 0
        self._told = (0, 0, 0, 0)  # (retransmits, timeouts, NAKs, stale resends) logged
        self._acked_clean = 0
        # the line's loss rate: go-backs per byte sent, both counts halved now and then
        self._loss_events = 0.0
        self._loss_bytes = 0.0
        self._seen = (0, 0)  # (go-backs, bytes delivered) at the last adaptation
        self.pumping = False  # a pump slice runs (the keep-alive thread then leaves it be)

    # ------------------------------------------------------------------ locking

    @contextmanager
    def locked(self) -> Iterator[None]:
        self._waiters += 1
        self._lock.acquire()
        self._waiters -= 1
        try:
            yield
        finally:
            self._lock.release()

    def others_waiting(self) -> bool:
        """Whether another thread waits for the lock (the holder should let go soon)."""
        return self._waiters > 0

    def let_others_in(self) -> None:
        """Between pump slices, let a thread that waits for the lock have its turn."""
        if self._waiters:
            time.sleep(0.0005)

    # ------------------------------------------------------------------ session state

    def new_session(self) -> None:
        """Fresh sequence numbers, coder context and adaptation (a handshake)."""
        self.ep.reset_session()
        self.ep.sender.window = min(START_WINDOW, self.max_window)
        self._last_retx = self._acked_clean = 0
        self._told = (0, 0, self.ep.counters.naks_received, 0)
        self._clean_timeouts = 0
        self._seen = (0, 0)
        self.ctx = SegmentContext(cycles_per_tick=self.ctx.cycles_per_tick)

    def credit(self) -> int:
        """Queue slots the host may still fill (PROTOCOL.md section 6)."""
        flow = self.dev.flow
        return flow.free - self.ep.sender.items_after(flow.ack)

    def clock_rate(self) -> float:
        return self.dev.clock.rate()

    def held_s(self, now: float) -> float:
        """Seconds of motion the device holds for certain: what its last report said it
        buffered, less what it has executed since (frames not acknowledged yet not counted)."""
        rate = self.clock_rate()
        if rate <= 0:
            return 0.0
        return self.flow.ahead_ticks(self.dev.flow, now, rate, 0) / rate

    # ------------------------------------------------------------------ I/O

    def urgent_frame(self, msg: Message) -> bytes:
        return encode_frame(Kind.URGENT, 0, self.ep.receiver.expected, encode_message(msg))

    def write(self, frames: list[bytes]) -> None:
        for f in frames:  # one write per frame: a wire's faults (duplication) act per frame
            self.t.write(f)
        if frames:
            self.last_tx = self.t.now()
            if self.ep.retransmits != self._told[0]:
                self._tell_retransmits()

    def _tell_retransmits(self) -> None:
        """Log when and why frames were resent: a timer that expired, a NAK from the device
        (a gap it saw), or a report that acknowledged nothing new (stale, a lossy line)."""
        s = self.ep.sender
        now = self.t.now()
        resent, timeouts, naks, stale = (
            s.retransmits - self._told[0],
            s.timeouts - self._told[1],
            self.ep.counters.naks_received - self._told[2],
            s.early_resends - self._told[3],
        )
        self._told = (s.retransmits, s.timeouts, self.ep.counters.naks_received, s.early_resends)
        why = ", ".join(
            f"{n} {what}"
            for n, what in ((timeouts, "timeout"), (naks, "NAK"), (stale, "stale report"))
            if n
        )
        srtt = s.rto.srtt
        ep = self.ep
        noisy = ep.bad_frames or ep.deframer.garbage_bytes or ep.counters.naks_received
        log.log(  # expected on a noisy line; on a clean one each is news
            logging.DEBUG if noisy else logging.INFO,
            "%s: resent %d frame(s) (%s): rto %.0f ms (floor %.0f), srtt %s, last byte from "
            "the device %.0f ms ago, device holds %.2f s of motion",
            self.name,
            resent,
            why or "duplicate",
            1000 * s.rto.rto,
            1000 * s.rto.floor,
            "-" if srtt is None else f"{1000 * srtt:.0f} ms",
            1000 * (now - self.last_rx),
            self.held_s(now),
        )

    def read(self, timeout: float) -> bytes:
        """Bytes from the port; :attr:`sent_after` is then the earliest the device can have
        sent them (when the read before this one returned: what it left had not arrived)."""
        self.sent_after = self._read_end
        data = self.t.read(timeout)
        self._read_end = self.t.now()
        return data

    def keepalive_interval(self) -> float:
        return min(self.watchdog_ms / 4000.0, self.timeout_s / 4)

    def _keepalive_due(self, now: float) -> bool:
        interval = self.keepalive_interval()
        return now - self.last_tx > interval or now - self.last_rx > self.timeout_s / 4

    def _take(self, data: bytes, now: float) -> None:
        """Hand received bytes to the endpoint and the tracker."""
        ep = self.ep
        before = ep.deframer.frames
        for inc in ep.feed(data, now, sent_after=self.sent_after):
            self.dev.handle(inc, now)
        if ep.deframer.frames > before:
            self.last_rx = now
            self.garbage_since_valid = 0
            self._waiting_since = None if ep.sender.idle() else now
        else:
            self.garbage_since_valid += len(data)

    def fatal(self) -> LinkError | None:
        """The failure that ended the session (reset, silence, port gone): None while the link
        works, a device that stopped on a fault included (it still answers)."""
        failure = self.dev.failure
        return None if failure is None or isinstance(failure, DeviceFault) else failure

    def pump(self, max_wait: float = SLICE_S, *, fault_ok: bool = False) -> None:
        """One slice: take what already arrived, write, wait for bytes (at most
        ``max_wait``), handle them, check liveness. Raises the tracker's failure (with
        ``fault_ok``, only one that ended the session: a device stopped by a fault still
        answers, and asking for its status is how its temperatures stay known)."""
        self._raise_failure(fault_ok)
        self.pumping = True
        try:
            self._pump(max_wait)
        finally:
            self.pumping = False
            self.last_pump = self.t.now()
        self._raise_failure(fault_ok)

    def _raise_failure(self, fault_ok: bool) -> None:
        failure = self.fatal() if fault_ok else self.dev.failure
        if failure is not None:
            raise failure

    def _pump(self, max_wait: float) -> None:
        ep = self.ep
        now = self.t.now()
        self.last_pump = now
        early = self.read(0.0)  # acknowledgements first: a due retransmission may be moot
        if early:
            self._take(early, now)
        if not ep.sender.idle() and self._waiting_since is None:
            self._waiting_since = now
        self.write(ep.flush(now))
        deadline = ep.next_deadline()
        wait = max_wait if deadline is None else min(max_wait, max(0.0, deadline - now))
        # what arrived already is news for the caller (a report that gives room): the slice
        # ends with it, not after a wait for more
        data = self.read(0.0 if early else wait)
        now = self.t.now()
        if data:
            self._take(data, now)
        self._adapt()
        if self._keepalive_due(now) and ep.sender.idle():
            ep.send(encode_message(GetStatus()))
            if self._waiting_since is None:
                self._waiting_since = now
        self.write(ep.flush(now))
        if self.fatal() is not None:
            return
        if (
            self._waiting_since is not None
            and now - self._waiting_since > self.timeout_s
            and now - self.last_rx > self.timeout_s
        ):
            log.warning("%s: device silent for %.1f s", self.name, now - self.last_rx)
            self.dev.failure = self.silent_error(self.garbage_since_valid, "")
            raise self.dev.failure

    def _adapt(self) -> None:
        """On a retransmission: shorter frames, half the window; every frame acknowledged
        without one grows them back (2 bytes, 1 frame): a noisy line settles on short frames
        that get through, a clean one on full ones. Frames never grow past the length the
        measured loss rate lets through about half the time (FRAME_LOSS_CEILING). A frame
        once sent keeps its size (its retransmissions are byte-identical), so frames start
        small and grow."""
        ep = self.ep
        retx = ep.retransmits
        sender = ep.sender
        clean, self._acked_clean = sender.acked_clean - self._acked_clean, sender.acked_clean
        rate = self.loss_rate()
        if retx > self._last_retx:
            floor = min(self.max_payload, self._payload_for(FRAME_LOSS_SHARE, rate))
            # shorter, down to the floor (never longer: a floor above the limit, early on
            # when little was measured, raised a noisy line's frames to full length)
            self.payload_limit = max(min(floor, self.payload_limit), int(self.payload_limit * 0.7))
            sender.window = max(MIN_WINDOW, sender.window // 2)
            log.debug(
                "%s: %d retransmissions; payload %d, window %d",
                self.name,
                retx - self._last_retx,
                self.payload_limit,
                sender.window,
            )
        elif clean:
            grown = min(self.max_payload, self.payload_ceiling(), self.payload_limit + 2 * clean)
            self.payload_limit = max(self.payload_limit, grown)
            sender.window = min(self.max_window, sender.window + clean)
        self._last_retx = retx
        if ep.byte_time == 0.0 and sender.silent_backoff:  # the fast path (a pty, USB)
            # no damaged byte and no NAK yet: nothing is lost on this path, and a timeout
            # could only be a scheduling delay of either process (the device model under
            # load): the longer floor; at the first sign of noise, the 25 ms one
            noisy = ep.bad_frames or ep.deframer.garbage_bytes or ep.counters.naks_received
            if noisy:
                sender.rto.floor, sender.rto.ceiling = RTO_FLOOR_S, self._ceiling
                sender.stale_after = STALE_REPORT_S
            else:  # a late answer, never a loss: wait longer from now on (CLEAN_RTO_FLOOR_MAX_S)
                most = min(CLEAN_RTO_FLOOR_MAX_S, self.timeout_s / 2)
                if sender.timeouts > self._clean_timeouts:
                    self._clean_floor = max(self._clean_floor, min(2 * self._clean_floor, most))
                wait = max(self._clean_floor, min(self._until_dry(), most))
                sender.rto.floor = wait
                sender.rto.ceiling = max(self._ceiling, wait)
                sender.stale_after = None
            self._clean_timeouts = sender.timeouts
        # (hysteresis: with two copies far fewer frames are lost, and so the measured rate)
        frame_loss = rate * (self.payload_limit + OVERHEAD)
        if frame_loss > COPY_LOSS:
            sender.copies = 2
        elif frame_loss < COPY_LOSS / 3:
            sender.copies = 1

    def _until_dry(self) -> float:
        """From the oldest frame in flight: how long the device can wait for it, what it holds
        of motion less CLEAN_DRY_MARGIN_S (0 with no queue item in flight). On a clean path the
        frame is late, not lost: while the device holds plenty, the host waits for its ACK."""
        sender = self.ep.sender
        if not sender.outstanding or not sender.unacked_items():
            return 0.0
        now = self.t.now()
        return now - sender.outstanding[0].sent_at + self.held_s(now) - CLEAN_DRY_MARGIN_S

    def loss_rate(self) -> float:
        """The line's loss rate: losses (go-backs) per byte that got through, both counts
        halved now and then so the estimate follows the line. Each frame acknowledged counts
        its bytes once, each go-back one frame lost. (Per byte *sent* it was far too low on
        a noisy line: a go-back resends the whole window, so the bytes sent grow much faster
        than the losses, and frames stayed long that almost never got through whole.)"""
        sender = self.ep.sender
        events = sender.go_backs
        delivered = sender.acked_bytes + sender.acked_frames * OVERHEAD
        lost = events - self._seen[0]
        self._loss_events += lost
        self._loss_bytes += delivered - self._seen[1] + lost * (self.payload_limit + OVERHEAD)
        self._seen = (events, delivered)
        while self._loss_bytes > LOSS_MEMORY_BYTES:
            self._loss_events /= 2
            self._loss_bytes /= 2
        return (self._loss_events + 0.5) / (self._loss_bytes + LOSS_PRIOR_BYTES)

    @staticmethod
    def _payload_for(share: float, rate: float) -> int:
        """The payload of a frame lost with about probability ``share`` at ``rate`` losses
        per byte (at least MIN_PAYLOAD)."""
        return max(MIN_PAYLOAD, int(share / rate) - OVERHEAD)

    def payload_floor(self) -> int:
        """The shortest payload worth sending on this line (FRAME_LOSS_SHARE)."""
        return self._payload_for(FRAME_LOSS_SHARE, self.loss_rate())

    def payload_ceiling(self) -> int:
        """The longest payload this line lets through about half the time (FRAME_LOSS_CEILING)."""
        return self._payload_for(FRAME_LOSS_CEILING, self.loss_rate())

    def wait(
        self,
        done: Callable[[], bool],
        timeout: float | None,
        what: str,
        pump: Callable[[], None] | None = None,
    ) -> None:
        """Pump (with ``pump``, else :meth:`pump`) until ``done()`` (LinkTimeout after
        ``timeout`` s)."""
        pump = pump or self.pump
        start = self.t.now()
        while True:
            self.let_others_in()
            with self.locked():
                if done():
                    return
                if timeout is not None and self.t.now() - start > timeout:
                    raise LinkTimeout(
                        f"{self.name}: {what} did not happen within {timeout:g} s "
                        f"(executed {self.dev.progress.items_done} of {self.items_sent} items)"
                    )
                pump()

    def send_immediate(self, msg: Message) -> None:
        """Queue one immediate command for the next flush (no credit needed)."""
        assert not msg.QUEUED
        self.ep.send(encode_message(msg))

    def silent_error(self, rx_bytes: int, when: str) -> DeviceSilent:
        p = self.dev.progress
        when = f" {when}" if when else ""
        if rx_bytes and self.ep.deframer.frames == 0:
            text = (
                f"{self.name}: {rx_bytes} bytes but no valid frame{when} within {self.timeout_s:g} s; "
                "wrong baud rate, or not a cdpr device (or one speaking protocol 1)?"
            )
        else:
            text = (
                f"{self.name}: no answer from the device{when} within {self.timeout_s:g} s "
                f"(last reported executed segment {p.segments_done}); is it powered and connected?"
            )
        return DeviceSilent(text, last_segment=p.segments_done, last_item=p.items_done)
