"""One end of the link (host or device): bytes in, bytes out, no I/O, no clock.

Combines the deframer, a go-back-N :class:`Sender` for this side's DATA frames and
a :class:`Receiver` for the peer's. ``feed`` consumes received bytes and returns
what the caller must handle; ``flush`` returns the frames to write now;
``next_deadline`` says when ``flush`` has something to do again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from firmware_protocol.framing import MAX_PAYLOAD, Deframer, Frame, Kind, encode_frame
from firmware_protocol.reliability import MAX_BACKOFF, Receiver, RtoEstimator, Sender


@dataclass(frozen=True)
class Incoming:
    """``kind``: ``data`` (in-order reliable payload), ``urgent`` (unsequenced) or ``flow`` (ACK/NAK payload)."""

    kind: str
    payload: bytes
    ack: int = 0  # the frame's ACK field (for ``flow``: the reports count every frame before it)


@dataclass
class EndpointCounters:
    frames_sent: int = 0
    frames_received: int = 0
    bytes_sent: int = 0
    bytes_received: int = 0
    naks_sent: int = 0
    naks_received: int = 0
    duplicates: int = 0
    rejected_frames: int = 0  # good CRC but refused by the owner (no room)


class Endpoint:
    """Sequenced, acknowledged framing for one side.

    ``accept(payload) -> bool`` (optional) is called for each in-order DATA payload
    before it is acknowledged; returning False leaves it unacknowledged (the peer
    retransmits). ``flow() -> bytes`` (optional) is the payload of every ACK/NAK
    this side sends; without it ACKs ride on outgoing DATA frames when possible.
    ``byte_time`` (seconds per byte on the wire, 0 if unknown) lets the RTT samples
    start when a frame has left the wire rather than when it was queued; it switches
    itself off when an acknowledgement proves the wire faster (USB CDC, a pty), and
    ``rto_fast`` (floor, max backoff) then replaces the retransmission timing, backing
    off only while the peer is silent (:attr:`Sender.silent_backoff`).
    ``stale_after`` (seconds, None: off): a report from the peer that acknowledges nothing
    new that long after the oldest frame left resends it once (:meth:`Sender.on_report`).
    ``renak``: a gap still open when the NAK holdoff ends is NAKed again (the host; the
    devices NAK once per holdoff as frames arrive, the AVR and the model alike).
    """

    def __init__(
        self,
        *,
        window: int = 8,
        rto_initial: float = 0.25,
        rto_floor: float = 0.02,
        rto_ceiling: float = 1.0,
        rto_max_backoff: int = MAX_BACKOFF,
        nak_holdoff: float = 0.01,
        accept: Callable[[bytes], bool] | None = None,
        flow: Callable[[], bytes] | None = None,
        byte_time: float = 0.0,
        window_bytes: int | None = None,
        rto_fast: tuple[float, int] | None = None,
        stale_after: float | None = None,
        renak: bool = False,
    ):
        self._window = window
        self.window_bytes = window_bytes
        self._rto_args = (rto_initial, rto_floor, rto_ceiling, rto_max_backoff)
        self._rto_fast = rto_fast  # (floor, max backoff) once the wire proves faster
        self._stale_after = stale_after  # Sender.stale_after
        self._calm_floor = 0.0  # the slow floor, for frames without queue items, once fast
        self._silent_backoff = False  # Sender.silent_backoff, once fast
        self.nak_holdoff = nak_holdoff
        self.renak = renak  # a gap still open when the holdoff ends is NAKed again
        self.accept = accept
        self.flow = flow
        self.byte_time = (
            byte_time  # wire time per byte, so RTT is measured from the end of transmission
        )
        self._wire_free = 0.0
        self.deframer = Deframer()
        self.counters = EndpointCounters()
        self._urgent: list[bytes] = []
        self.reset_session()

    def reset_session(self) -> None:
        """Start sequence numbers from 0 on both directions (after HELLO)."""
        self.sender = Sender(self._window, RtoEstimator(*self._rto_args), self.window_bytes)
        self.sender.calm_floor = self._calm_floor
        self.sender.silent_backoff = self._silent_backoff
        self.sender.stale_after = self._stale_after
        self.receiver = Receiver()
        self._ack_due = False
        self._nak_due = False
        self._nak_later: float | None = None  # a NAK held back by the holdoff: due then
        self._last_nak = (-1, -1e9)

    def _fast_path(self) -> None:
        """No slow UART behind this path: the fast retransmission timing, if one was given."""
        if self._rto_fast is None:
            return
        floor, backoff = self._rto_fast
        initial, calm, ceiling, _ = self._rto_args
        self._calm_floor = self.sender.calm_floor = max(self._calm_floor, calm)
        self._rto_args = (initial, floor, ceiling, backoff)
        self._silent_backoff = self.sender.silent_backoff = True
        rto = self.sender.rto
        rto.floor, rto.max_backoff = floor, max(1, backoff)
        rto.reset_backoff()

    @property
    def retransmits(self) -> int:
        return self.sender.retransmits

    @property
    def bad_frames(self) -> int:
        return self.deframer.bad_frames + self.deframer.bad_headers

    # ------------------------------------------------------------------ receive

    def feed(self, data: bytes, now: float, sent_after: float | None = None) -> list[Incoming]:
        """Deframe ``data`` and :meth:`process` the frames (``sent_after``: see there)."""
        self.counters.bytes_received += len(data)
        if data:  # the peer is alive: even a damaged frame says so
            self.sender.heard(now)
        return self.process(self.deframer.feed(data), now, sent_after)

    def process(
        self, frames: list[Frame], now: float, sent_after: float | None = None
    ) -> list[Incoming]:
        """Handle already deframed frames: acks, naks, in-order delivery. ``sent_after``:
        the earliest the peer can have sent them, if the caller knows (bytes that waited in
        a buffer): a report is stale only if it was sent long enough after a frame left
        (:meth:`Sender.on_report`), not merely read that late."""
        out: list[Incoming] = []
        if self.deframer.rejected:
            for kind, seq in self.deframer.rejected:
                if kind == Kind.DATA and seq == self.receiver.expected:
                    self._want_nak(now)
            self.deframer.rejected.clear()
        for frame in frames:
            self.counters.frames_received += 1
            self.sender.heard(now)
            if frame.kind == Kind.URGENT:
                out.append(Incoming("urgent", frame.payload))
                continue
            if (
                self.byte_time
                and self.sender.outstanding
                and frame.ack != self.sender.base
                and not self.sender.outstanding[0].retransmitted
                and self.sender.outstanding[0].sent_at > now
            ):
                # (a resent frame proves nothing: the acknowledgement can be the first
                # copy's, and the copy's end on the wire is in the future. Taken as
                # proof, it put a 250000-baud UART on the fast timing: a 3 ms timeout
                # without backoff that stormed the AVR with go-backs.)
                self.byte_time = (
                    0.0  # acknowledged before it could have left: the wire is faster (USB, pty)
                )
                self._fast_path()
            if frame.kind == Kind.NAK:
                self.counters.naks_received += 1
                self.sender.on_nak(frame.ack, now)
            else:
                self.sender.on_report(frame.ack, now, sent_after)
            if frame.kind != Kind.DATA:
                if frame.payload:
                    out.append(Incoming("flow", frame.payload, frame.ack))
                continue
            verdict = self.receiver.classify(frame.seq)
            if verdict == Receiver.NEW:
                if self.accept is None or self.accept(frame.payload):
                    self.receiver.accept()
                    out.append(Incoming("data", frame.payload))
                else:
                    self.counters.rejected_frames += 1
                self._ack_due = True
            elif verdict == Receiver.DUPLICATE:
                self.counters.duplicates += 1
                self._ack_due = True
            else:
                self._want_nak(now)
        return out

    def _want_nak(self, now: float) -> None:
        """A gap (or a damaged frame where the expected one should be): NAK now, or (with
        ``renak``), within the holdoff of a NAK for the same number, once the holdoff ends. The gap is still
        open then (frames behind it keep coming, the one it lacks does not) and the first
        NAK or the go-back it asked for may have been lost too: waiting for the peer's
        timeout would stall the stream on a noisy line."""
        expected, when = self._last_nak
        if expected != self.receiver.expected or now - when >= self.nak_holdoff:
            self._nak_due = True
        elif self.renak:
            self._nak_later = when + self.nak_holdoff

    # ------------------------------------------------------------------ send

    def send(self, payload: bytes, items: int = 0, ticks: int = 0) -> None:
        """Queue a reliable DATA payload; ``items`` is its move-queue slot count, ``ticks``
        the device time of motion it carries."""
        if len(payload) > MAX_PAYLOAD:
            raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
        self.sender.queue(payload, items, ticks)

    def send_urgent(self, payload: bytes) -> None:
        self._urgent.append(payload)

    def request_ack(self) -> None:
        self._ack_due = True

    def next_deadline(self) -> float | None:
        if self._urgent or self._ack_due or self._nak_due:
            return -1.0
        deadline = self.sender.next_deadline()
        if self._nak_later is not None:
            deadline = self._nak_later if deadline is None else min(deadline, self._nak_later)
        return deadline

    def flush(self, now: float) -> list[bytes]:
        expected = self.receiver.expected
        if self._nak_later is not None and now >= self._nak_later:
            self._nak_later = None
            if self._last_nak[0] == expected:  # the gap is still open
                self._nak_due = True
        frames = [encode_frame(Kind.URGENT, 0, expected, p) for p in self._urgent]
        self._urgent.clear()
        data = self.sender.frames_to_send(now)
        if self.byte_time:  # frames leave one after the other, after what is still on the wire
            wire = max(now, self._wire_free) + sum(map(len, frames)) * self.byte_time
        for seq, p in data:
            frame = encode_frame(Kind.DATA, seq, expected, p)
            frames.append(frame)
            if self.byte_time:
                wire += len(frame) * self.byte_time
                self.sender.stamp(seq, wire)
        if self._nak_due:
            frames.append(encode_frame(Kind.NAK, 0, expected, self.flow() if self.flow else b""))
            self.counters.naks_sent += 1
            self._last_nak = (expected, now)
        elif self._ack_due and (self.flow is not None or not data):
            frames.append(encode_frame(Kind.ACK, 0, expected, self.flow() if self.flow else b""))
        self._ack_due = self._nak_due = False
        if self.byte_time and frames:
            self._wire_free = max(now, self._wire_free) + sum(map(len, frames)) * self.byte_time
        self.counters.frames_sent += len(frames)
        self.counters.bytes_sent += sum(map(len, frames))
        return frames
