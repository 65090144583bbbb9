"""Streaming motion: credit, time watermarks and the window decide how much of a batch
goes out (PROTOCOL.md section 6).

A part of the link: it works on the link's :class:`~cdprhost.link.core.LinkCore` and
asks the session set-up (:class:`SessionConfig`: the configured start threshold, and a
new configuration when the measured clock rate has moved) for nothing else.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from cdprhost.link.core import LinkCore
from cdprhost.link.errors import StepRateError
from cdprhost.link.events import Identity
from firmware_protocol.messages import Flag
from firmware_protocol.segments import SegmentBatch, encode_segments, peak_step_rates


class SessionConfig(Protocol):
    """What the stream needs of the session set-up."""

    configured_rate: float
    start_ticks: int

    def configure(self) -> None: ...


class SegmentFeed:
    """The segment stream of one link (its core): ``feed``, ``queue_segments``."""

    def __init__(self, core: LinkCore, session: SessionConfig):
        self.core = core
        self.session = session

    def ahead_ticks(self) -> float:
        """Device ticks of motion held ahead of the device's now (estimated; see flow.py)."""
        c = self.core
        flow = c.dev.flow
        return c.flow.ahead_ticks(
            flow, c.t.now(), c.clock_rate(), c.ep.sender.ticks_after(flow.ack)
        )

    def _window_room(self) -> int:
        """Payload bytes the window can still take (sent or queued frames count)."""
        s = self.core.ep.sender
        if s.window_free <= 0:
            return 0
        cap = s.window_bytes or 1 << 20
        queued = sum(len(o.payload) for o in s.outstanding) + sum(len(b.payload) for b in s.backlog)
        return max(0, cap - queued)

    def _sendable(self, ticks: np.ndarray) -> int:
        """How many of the segments with durations ``ticks`` may go now."""
        c = self.core
        slots = c.credit()
        if slots <= 0:
            return 0
        rate = c.clock_rate()
        if abs(rate - self.session.configured_rate) > 0.1 * self.session.configured_rate:
            self.session.configure()
        moving = bool(c.dev.flow.flags & Flag.MOVING)
        if c.ep.sender.copies > 1:
            # a line that loses half its frames: top up all the time rather than refill
            # from the low watermark (a refill then takes many rounds, and a stall of
            # either process meanwhile could let the device run dry)
            c.flow.filling = True
        room = c.flow.room_ticks(self.ahead_ticks(), rate, moving, self.session.start_ticks)
        if room <= 0:
            return 0
        window = self._window_room()
        if window <= 0:
            return 0
        limit = min(len(ticks), slots, max(8, window // 2))
        cum = np.cumsum(ticks[:limit])
        return min(limit, int(np.searchsorted(cum, room, side="right")) + 1)

    def _send_segments(self, batch: SegmentBatch, i: int, j: int) -> None:
        c = self.core
        sub = batch[i:j]
        data, offsets = encode_segments(sub, c.ctx)
        n = j - i
        pos = 0
        limit = c.payload_limit
        ticks = sub.ticks
        while pos < n:
            end = int(np.searchsorted(offsets, offsets[pos] + limit, side="right")) - 1
            end = max(pos + 1, min(end, n))
            c.ep.send(
                data[offsets[pos] : offsets[end]],
                items=end - pos,
                ticks=int(ticks[pos:end].sum()),
            )
            pos = end
        c.items_sent += n
        c.segments_sent += n
        c.write(c.ep.flush(c.t.now()))

    def check_step_rates(self, batch: SegmentBatch, identity: Identity) -> None:
        """Raise :class:`StepRateError` for a segment over the device's max step rate, or
        shorter than the shortest one it takes (CAPS)."""
        caps = self.core.dev.caps
        if caps is not None and len(batch) and int(batch.ticks.min()) < caps.min_segment_ticks:
            k = int(np.argmin(batch.ticks))
            raise StepRateError(
                f"segment {k} of the batch lasts {int(batch.ticks[k])} ticks; the device takes "
                f"no segment under {caps.min_segment_ticks} ticks"
            )
        rates = peak_step_rates(batch, identity.clock_hz)
        over = np.flatnonzero((rates > identity.max_step_rate).any(axis=1))
        if over.size:
            k = int(over[0])
            raise StepRateError(
                f"segment {k} of the batch: peak step rate {rates[k].max():.0f}/s exceeds the device "
                f"limit {identity.max_step_rate}/s"
            )

    def feed(
        self,
        batch: SegmentBatch,
        identity: Identity,
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
            self.check_step_rates(batch, identity)
        c = self.core
        until = c.t.now() + max_wait
        i = start
        while i < n:
            c.let_others_in()
            with c.locked():
                if c.dev.failure is not None:
                    raise c.dev.failure
                k = self._sendable(batch.ticks[i:n])
                if k > 0:
                    self._send_segments(batch, i, i + k)
                    i += k
                    continue
                now = c.t.now()
                if now >= until:
                    break
                wake = c.flow.wake_in(
                    self.ahead_ticks(), c.clock_rate(), bool(c.dev.flow.flags & Flag.MOVING)
                )
                # below the low watermark already: only a report can give room
                wait = until - now if not wake else min(until - now, wake)
                c.pump(min(wait, 0.25))
        return i
