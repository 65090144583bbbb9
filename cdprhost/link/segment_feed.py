# mypy: disable-error-code="misc"
# (mixin methods typed with the class that uses them as ``self``: mypy only allows
# supertypes there, but the bodies are then checked against HostLink in full)
"""Streaming motion: credit, time watermarks and the window decide how much of a batch
goes out (PROTOCOL.md section 6).

A mixin of :class:`cdprhost.link.host_link.HostLink` (its methods take the link as
``self``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cdprhost.link.errors import LinkTimeout, StepRateError
from firmware_protocol.messages import Flag, Flush
from firmware_protocol.segments import SegmentBatch, encode_segments, peak_step_rates

if TYPE_CHECKING:
    from cdprhost.link.host_link import HostLink


class SegmentFeed:
    """HostLink's segment streaming: ``feed``, ``queue_segments``, ``flush``."""

    def _credit(self: HostLink) -> int:
        flow = self._dev.flow
        return flow.free - self._ep.sender.items_after(flow.ack)

    def ahead_ticks(self: HostLink) -> float:
        """Device ticks of motion held ahead of the device's now (estimated; see flow.py)."""
        flow = self._dev.flow
        return self._flow.ahead_ticks(
            flow, self._t.now(), self.clock_rate, self._ep.sender.ticks_after(flow.ack)
        )

    def _window_room(self: HostLink) -> int:
        """Payload bytes the window can still take (sent or queued frames count)."""
        s = self._ep.sender
        if s.window_free <= 0:
            return 0
        cap = s.window_bytes or 1 << 20
        queued = sum(len(o.payload) for o in s.outstanding) + sum(len(b.payload) for b in s.backlog)
        return max(0, cap - queued)

    def _sendable(self: HostLink, ticks: np.ndarray) -> int:
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

    def _send_segments(self: HostLink, batch: SegmentBatch, i: int, j: int) -> None:
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

    def check_step_rates(self: HostLink, batch: SegmentBatch) -> None:
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
        self: HostLink,
        batch: SegmentBatch,
        start: int = 0,
        max_wait: float = 0.0,
        end: int | None = None,
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

    def queue_segments(self: HostLink, batch: SegmentBatch, timeout: float | None = None) -> range:
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

    def flush(self: HostLink) -> None:
        """FLUSH: the motion sent so far may start now (end of a stream, a pause)."""
        self.send(Flush())
