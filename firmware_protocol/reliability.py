"""Reliable ordered delivery: go-back-N sender and in-order receiver, no I/O.

Both are driven by the caller with explicit times (``now`` in seconds), so they
run the same under a virtual clock in tests and a real clock on a port.

- Sequence numbers are 8 bit; the window is at most 127 frames.
- ACK carries the next sequence number expected (cumulative); NAK carries the
  same and asks for everything from it again (go-back-N).
- The retransmission timeout follows RFC 6298 (SRTT, RTTVAR, Karn's rule: no
  samples from retransmitted frames) with exponential backoff, floor and ceiling.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

SEQ_MOD = 256
MAX_WINDOW = 127


class RtoEstimator:
    """Adaptive retransmission timeout (RFC 6298) with floor/ceiling and backoff."""

    def __init__(self, initial: float = 0.25, floor: float = 0.02, ceiling: float = 1.0):
        self.floor = floor
        self.ceiling = ceiling
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
        self._backoff = min(self._backoff * 2, 64)

    def reset_backoff(self) -> None:
        self._backoff = 1


@dataclass
class _Outstanding:
    seq: int
    payload: bytes
    items: int
    sent_at: float
    retransmitted: bool = False


class Sender:
    """Go-back-N sender: a window of sent-but-unacknowledged frames plus a backlog."""

    def __init__(self, window: int = 8, rto: RtoEstimator | None = None):
        if not 1 <= window <= MAX_WINDOW:
            raise ValueError(f"window must be 1..{MAX_WINDOW}")
        self.window = window
        self.rto = rto or RtoEstimator()
        self.next_seq = 0
        self.outstanding: deque[_Outstanding] = deque()
        self.backlog: deque[tuple[bytes, int, int]] = deque()  # payload, items, cumulative items
        self.items_queued = 0
        self._cum_items: dict[int, int] = {}  # seq -> cumulative items through that frame
        self.retransmits = 0
        self.timeouts = 0
        self._resend = False
        self._went_back: tuple[int, float] = (-1, -1e9)

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
        return sum(o.items for o in self.outstanding) + sum(b[1] for b in self.backlog)

    def items_after(self, ack: int) -> int:
        """Queue items in every frame from sequence number ``ack`` on (sent or not)."""
        return self.items_queued - self._cum_items.get((ack - 1) % SEQ_MOD, 0)

    def queue(self, payload: bytes, items: int = 0) -> None:
        self.items_queued += items
        self.backlog.append((payload, items, self.items_queued))

    def on_ack(self, ack: int, now: float) -> int:
        """Release frames before ``ack``; returns how many were released."""
        n = (ack - self.base) % SEQ_MOD
        if n == 0 or n > len(self.outstanding):
            return 0
        last = None
        for _ in range(n):
            last = self.outstanding.popleft()
        if last is not None and not last.retransmitted:
            self.rto.sample(now - last.sent_at)
        else:
            self.rto.reset_backoff()
        return n

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
        self._resend = True
        self._went_back = (self.base, now)

    def stamp(self, seq: int, sent_at: float) -> None:
        """Set when frame ``seq`` actually left (end of its transmission)."""
        for o in self.outstanding:
            if o.seq == seq:
                o.sent_at = sent_at
                return

    def next_deadline(self) -> float | None:
        if self._resend or (self.backlog and len(self.outstanding) < self.window):
            return -1.0
        if not self.outstanding:
            return None
        return self.outstanding[0].sent_at + self.rto.rto

    def frames_to_send(self, now: float) -> list[tuple[int, bytes]]:
        """Retransmissions that are due (timeout or NAK) and new frames the window allows."""
        out: list[tuple[int, bytes]] = []
        if (
            self.outstanding
            and not self._resend
            and now >= self.outstanding[0].sent_at + self.rto.rto
        ):
            self.timeouts += 1
            self.rto.back_off()
            self._go_back(now)
        if self._resend:
            self._resend = False
            for o in self.outstanding:
                o.sent_at = now
                o.retransmitted = True
                self.retransmits += 1
                out.append((o.seq, o.payload))
        while self.backlog and len(self.outstanding) < self.window:
            payload, items, cum = self.backlog.popleft()
            self._cum_items[self.next_seq] = cum
            o = _Outstanding(self.next_seq, payload, items, now)
            self.next_seq = (self.next_seq + 1) % SEQ_MOD
            self.outstanding.append(o)
            out.append((o.seq, o.payload))
        return out


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
