"""Reliable ordered delivery: go-back-N sender and in-order receiver, no I/O.

Both are driven by the caller with explicit times (``now`` in seconds), so they
run the same under a virtual clock in tests and a real clock on a port.

- Sequence numbers are 8 bit; the window is at most 127 frames.
- ACK carries the next sequence number expected (cumulative); NAK carries the
  same and asks for everything from it again (go-back-N).
- The retransmission timeout follows RFC 6298 (SRTT, RTTVAR, Karn's rule: no
  samples from retransmitted frames) with exponential backoff, floor and ceiling; its
  timer restarts at every acknowledgement that releases frames (RFC 6298 5.3).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

SEQ_MOD = 256
MAX_WINDOW = 127
MAX_BACKOFF = 4
SILENT_S = 0.15  # a peer that sent no byte for this long is silent (Sender.silent_backoff)


class RtoEstimator:
    """Adaptive retransmission timeout (RFC 6298) with floor/ceiling and backoff."""

    def __init__(
        self,
        initial: float = 0.25,
        floor: float = 0.02,
        ceiling: float = 1.0,
        max_backoff: int = MAX_BACKOFF,
    ):
        self.floor = floor
        self.ceiling = ceiling
        self.max_backoff = max(1, max_backoff)
        self.srtt: float | None = None
        self.rttvar = 0.0
        self._base = initial
        self._backoff = 1

    @property
    def rto(self) -> float:
        return min(self.ceiling, max(self.floor, self._base) * self._backoff)

    def sample(self, rtt: float) -> None:
        rtt = max(0.0, rtt)
        if self.srtt is None:
            self.srtt, self.rttvar = rtt, rtt / 2
        else:
            self.rttvar = 0.75 * self.rttvar + 0.25 * abs(self.srtt - rtt)
            self.srtt = 0.875 * self.srtt + 0.125 * rtt
        self._base = self.srtt + max(0.002, 4 * self.rttvar)
        self._backoff = 1

    def back_off(self) -> None:
        """Double the timeout after a timeout, at most ``max_backoff`` times (4x by default;
        1: never): a serial line loses frames to noise, not congestion, so waiting longer
        only slows the retry."""
        self._backoff = min(self._backoff * 2, self.max_backoff)

    def reset_backoff(self) -> None:
        self._backoff = 1


@dataclass
class _Outstanding:
    seq: int
    payload: bytes
    items: int
    sent_at: float
    retransmitted: bool = False
    first_sent: float = 0.0


@dataclass
class _Queued:
    payload: bytes
    items: int
    cum_items: int  # queue items in every frame queued so far, this one included
    cum_ticks: int  # device ticks of motion likewise


class Sender:
    """Go-back-N sender: a window of sent-but-unacknowledged frames plus a backlog.

    The window is bounded in frames (``window``, at most 127) and, when ``window_bytes``
    is given, in payload bytes (what the receiver can buffer)."""

    def __init__(
        self, window: int = 8, rto: RtoEstimator | None = None, window_bytes: int | None = None
    ):
        if not 1 <= window <= MAX_WINDOW:
            raise ValueError(f"window must be 1..{MAX_WINDOW}")
        self.window = window
        self.window_bytes = window_bytes
        self.rto = rto or RtoEstimator()
        # while no queue items are in flight (only keep-alives, status requests) nothing
        # is resent before this: nothing waits on them, and on a fast path (3 ms floor) a
        # scheduling hiccup of either side would count as a loss on a clean idle link
        self.calm_floor = 0.0
        # a report that acknowledges nothing new this long after the oldest frame left (and
        # after the last progress) resends it once, before its timeout (None: never)
        self.stale_after: float | None = None
        self.next_seq = 0
        self.outstanding: deque[_Outstanding] = deque()
        self.backlog: deque[_Queued] = deque()
        self.items_queued = 0
        self.ticks_queued = 0
        self._bytes_out = 0
        self._items_out = 0  # queue items in the outstanding frames
        self._cum: dict[int, tuple[int, int]] = {}  # seq -> (cumulative items, ticks) through it
        # every DATA frame leaves this many times back to back (2 on a line that loses about
        # half of its frames: a copy lost to noise is then usually made good by the other
        # at once, instead of by a NAK or a timeout one round later; the receiver discards
        # the copy it does not need as a duplicate and acknowledges it again)
        self.copies = 1
        # back off only while the peer is silent (no byte for SILENT_S), and resend only the
        # oldest frame, a probe, while nothing came since it left: a timeout while the peer
        # is heard is a frame or an acknowledgement lost to noise, and a longer wait only
        # stalls the stream (False: back off at every timeout, resend the whole window)
        self.silent_backoff = False
        self._heard_at = -1e9  # when a valid frame from the peer last arrived
        self.extra_copies = 0  # copies sent beyond the first
        self.retransmits = 0
        self.timeouts = 0
        self.go_backs = 0  # resends of the window (a timeout or a NAK): losses seen
        self.early_resends = 0  # go-backs on a stale report (stale_after)
        self.acked_clean = 0  # frames acknowledged that had been sent once
        self.acked_bytes = 0  # payload bytes of the frames acknowledged, each counted once
        self.acked_frames = 0
        self._resend = False
        self._went_back: tuple[int, float] = (-1, -1e9)
        # when an acknowledgement last released frames: the timer restarts there (RFC 6298
        # 5.3), so frames that wait in a busy receiver's buffer behind others it is still
        # working through do not time out while it acknowledges them one by one
        self._advanced_at = -1e9

    @property
    def base(self) -> int:
        return self.outstanding[0].seq if self.outstanding else self.next_seq

    @property
    def window_free(self) -> int:
        return max(0, self.window - len(self.outstanding) - len(self.backlog))

    def idle(self) -> bool:
        return not self.outstanding and not self.backlog

    def unacked_items(self) -> int:
        """Queue items in frames the peer has not acknowledged yet (sent or not)."""
        return sum(o.items for o in self.outstanding) + sum(b.items for b in self.backlog)

    def _through(self, ack: int) -> tuple[int, int]:
        """Cumulative (items, ticks) of every frame before sequence number ``ack``."""
        if ack == self.next_seq and not self.backlog:
            return self.items_queued, self.ticks_queued
        return self._cum.get((ack - 1) % SEQ_MOD, (0, 0))

    def items_after(self, ack: int) -> int:
        """Queue items in every frame from sequence number ``ack`` on (sent or not)."""
        return self.items_queued - self._through(ack)[0]

    def ticks_after(self, ack: int) -> int:
        """Device ticks of motion in every frame from sequence number ``ack`` on (sent or not)."""
        return self.ticks_queued - self._through(ack)[1]

    def queue(self, payload: bytes, items: int = 0, ticks: int = 0) -> None:
        self.items_queued += items
        self.ticks_queued += ticks
        self.backlog.append(_Queued(payload, items, self.items_queued, self.ticks_queued))

    def on_ack(self, ack: int, now: float) -> int:
        """Release frames before ``ack``; returns how many were released."""
        n = (ack - self.base) % SEQ_MOD
        if n == 0 or n > len(self.outstanding):
            return 0
        last = None
        clean = 0
        for _ in range(n):
            last = self.outstanding.popleft()
            self._bytes_out -= len(last.payload)
            self._items_out -= last.items
            self.acked_bytes += len(last.payload)
            clean += not last.retransmitted
        self.acked_clean += clean
        self.acked_frames += n
        self._advanced_at = now
        if last is not None and not last.retransmitted:
            self.rto.sample(now - last.sent_at)
        else:
            self.rto.reset_backoff()
        return n

    def on_report(self, ack: int, now: float, sent_after: float | None = None) -> None:
        """An ACK or DATA frame from the peer: release frames before ``ack``. If it releases
        none although the oldest outstanding frame left ``stale_after`` ago (and nothing was
        released since) and queue items are in flight, that frame was lost with nothing
        behind it to show the gap: resend from it now. A frame already resent waits twice
        as long: the peer is alive (it reports) and still without it, so its copies were
        lost too, and the timeout, backed off by then, would let the peer's queue run dry
        (at most one resend per 40 ms this way; a peer that stops reporting is left to the
        timeout and its backoff)."""
        if self.on_ack(ack, now) or self.stale_after is None or self._resend:
            return
        if not self._items_out or self.outstanding[0].seq != ack:
            return  # keep-alives and status requests wait for their timeout (calm_floor)
        oldest = self.outstanding[0]
        wait = 2 * self.stale_after if oldest.retransmitted else self.stale_after
        # judged by when the report can have been sent at the earliest (``sent_after``, if
        # known): a report that waited in a buffer while this side was busy was written
        # before the frame arrived, and resending then was a spurious retransmission
        sent = now if sent_after is None else min(now, sent_after)
        if sent - self._timer_start() >= wait:
            self.early_resends += 1
            self._go_back(now)

    def heard(self, now: float) -> None:
        """A valid frame from the peer arrived (it is alive)."""
        self._heard_at = now

    def on_nak(self, ack: int, now: float) -> None:
        """Release frames before ``ack``, then resend from ``ack`` unless that was just done."""
        self.on_ack(ack, now)
        if not self.outstanding or self.outstanding[0].seq != ack:
            return
        seq, when = self._went_back
        holdoff = 0.5 * (self.rto.srtt if self.rto.srtt is not None else self.rto.rto)
        if seq == ack and now - when < holdoff:
            return
        self._go_back(now)

    def _go_back(self, now: float) -> None:
        self.go_backs += 1
        self._resend = True
        self._went_back = (self.base, now)

    def stamp(self, seq: int, sent_at: float) -> None:
        """Set when frame ``seq`` actually left (end of its transmission)."""
        for o in self.outstanding:
            if o.seq == seq:
                o.sent_at = sent_at
                return

    def next_deadline(self) -> float | None:
        if self._resend or (self.backlog and self._room_for(len(self.backlog[0].payload))):
            return -1.0
        if not self.outstanding:
            return None
        return self._timer_start() + self._timeout()

    def _timer_start(self) -> float:
        """The oldest outstanding frame's send time, or the last acknowledgement that released
        frames if that came later (the timer restarts on progress)."""
        return max(self.outstanding[0].sent_at, self._advanced_at)

    def _timeout(self) -> float:
        """The retransmission timeout: the calm floor at least while no queue items wait
        (sent or not)."""
        rto = self.rto.rto
        return rto if self._items_out or self.backlog else max(rto, self.calm_floor)

    def frames_to_send(self, now: float) -> list[tuple[int, bytes]]:
        """Retransmissions that are due (timeout or NAK) and new frames the window allows."""
        out: list[tuple[int, bytes]] = []
        probe = False
        if self.outstanding and not self._resend and now >= self._timer_start() + self._timeout():
            self.timeouts += 1
            if not self.silent_backoff:
                self.rto.back_off()
            else:
                # nothing since the oldest frame last left: ask with that frame alone; nothing
                # at all for SILENT_S (longer than a device's reports are apart, about a
                # quarter of a second at 1x): the device is silent, and the timeout doubles
                probe = self._heard_at < self.outstanding[0].sent_at
                if now - self._heard_at >= SILENT_S:
                    self.rto.back_off()
            self._go_back(now)
        if self._resend and probe:  # a silent peer: the oldest frame alone asks if it is back
            self._resend = False
            o = self.outstanding[0]
            o.sent_at, o.retransmitted = now, True
            self.retransmits += 1
            out += [(o.seq, o.payload)] * self.copies
        if self._resend:
            self._resend = False
            for o in self.outstanding:
                o.sent_at = now
                o.retransmitted = True
                self.retransmits += 1
                out += [(o.seq, o.payload)] * self.copies
        while self.backlog and self._room_for(len(self.backlog[0].payload)):
            q = self.backlog.popleft()
            self._cum[self.next_seq] = (q.cum_items, q.cum_ticks)
            o = _Outstanding(self.next_seq, q.payload, q.items, now, first_sent=now)
            self.next_seq = (self.next_seq + 1) % SEQ_MOD
            self.outstanding.append(o)
            self._bytes_out += len(q.payload)
            self._items_out += q.items
            out += [(o.seq, o.payload)] * self.copies
        self.extra_copies += len(out) - len(out) // self.copies
        return out

    def _room_for(self, size: int) -> bool:
        if len(self.outstanding) >= self.window:
            return False
        cap = self.window_bytes
        return cap is None or not self.outstanding or self._bytes_out + size <= cap


class Receiver:
    """In-order receiver: accepts only the expected sequence number."""

    NEW, DUPLICATE, GAP = "new", "duplicate", "gap"

    def __init__(self) -> None:
        self.expected = 0

    def classify(self, seq: int) -> str:
        d = (seq - self.expected) % SEQ_MOD
        if d == 0:
            return self.NEW
        return self.GAP if d <= MAX_WINDOW else self.DUPLICATE

    def accept(self) -> None:
        self.expected = (self.expected + 1) % SEQ_MOD
