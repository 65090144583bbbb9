"""Streaming motion: credit, time watermarks and the window decide how much of a batch
goes out (PROTOCOL.md section 6).

A part of the link: it works on the link's :class:`~cdprhost.link.core.LinkCore` and
asks the session set-up (:class:`SessionConfig`: the configured start threshold, and a
new configuration when the measured clock rate has moved) for nothing else.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from typing import Protocol

import numpy as np

from cdprhost.link.collector import keep_pauses_short
from cdprhost.link.core import LinkCore
from cdprhost.link.errors import StepRateError
from cdprhost.link.events import DeviceCaps, Identity
from cdprhost.link.ring_room import RingRoom
from cdprhost.motion.block_cuts import BLOCK_FRAME_BYTES
from firmware_protocol.block_ring import block_entries
from firmware_protocol.messages import Flag, GetStatus
from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.schedule_block import MAX_CHUNKS
from firmware_protocol.schedule_fit import plan_schedules
from firmware_protocol.segments import (
    SEGMENT_MAX_BYTES,
    SegmentBatch,
    SegmentContext,
    encode_block_for,
    encode_segments,
    peak_step_rates,
)
from firmware_protocol.step_schedule import AxisSchedule, predictable

log = logging.getLogger("cdprhost.link.host_link")

#: ramps (schedules fitted in Python, milliseconds each) sent per turn of the feed, which
#: holds the link's lock meanwhile: the keep-alive and the reports wait that long
RAMPS_PER_TURN = 16
#: while the device has no room (its window, slots or ring), the feed fits the blocks the
#: next ramps must carry, at most PREFIT_RAMPS a wait and PREFIT_AHEAD segments ahead: the
#: send the next report allows then only encodes them (a block's fit takes about 0.5 ms of
#: Python, and the AVR engine's ring of fast ramps holds about 30 ms)
PREFIT_RAMPS = 4
PREFIT_AHEAD = 32
#: the ramps' fits may take this share of the host's time since the feed began, and at
#: most FIT_TURN_S in one turn (a fast stream of a simulated device gets few blocks for its
#: ramps: the rest run on the device's own stepping, PROTOCOL.md 5.5), until the fitter is
#: fast enough for every ramp (docs/step-engine.md section 7)
FIT_SHARE = 0.1
FIT_TURN_S = 0.05
#: a ramp's fit, before one was timed (four axes, about 5 ms in Python: bench/step_schedule.py)
RAMP_FIT_S = 0.005
#: the most payload bytes a frame of the stream carries, however long the line lets frames
#: grow (a segment longer than that, with its schedule block, still goes alone): a device
#: reads a frame only once it is whole, so its segments reach the queue a frame's time on
#: the wire and its check later. At 250000 baud a full 120-byte frame of a print's short
#: segments (27 of 0.5 ms) is 5.2 ms on the wire and 4-6 ms in the AVR's check; with the
#: step engine's queue of 64 (32 ms of them) and the host's own delays that ran the queue
#: dry within seconds at 2,000 segments/s. Frames of 48 bytes (about 11 such segments,
#: 2.4 ms on the wire) cost the AVR no more CPU a segment, and the stream ran 30 s exact in
#: most runs (docs/step-engine.md section 10: 64 and 36 bytes ran dry sooner).
STREAM_FRAME_BYTES = 48


def wire_schedules(
    batch: SegmentBatch,
    ctx: SegmentContext,
    tol_cycles: float,
    max_payload: int,
    fit_budget_s: float | None = None,
    needed: np.ndarray | None = None,
    fitted: Mapping[int, Mapping[int, AxisSchedule]] | None = None,
) -> dict[tuple[int, int], AxisSchedule]:
    """The schedule blocks ``batch`` carries (PROTOCOL.md 5.5), by ``(segment, axis)``:
    every moving axis whose prediction the device cannot make or that strays past
    ``tol_cycles`` (:func:`plan_schedules`), as long as its segment with the block fits
    ``max_payload`` bytes and the axis fits ``MAX_CHUNKS``. An axis the device predicts
    always keeps its block (the device refuses a prediction that strays); an unpredictable
    axis whose block does not fit is left to the device's own stepping of the profile
    (3.0's fallback, until segments are cut where their blocks are too long:
    docs/step-engine.md section 7). ``fit_budget_s``: host time the ramps' fits may take
    (they run in Python, milliseconds a ramp); the ramps after it go without a block too,
    except those ``needed`` marks (bool per segment: faster at their peak than the device
    steps without a block, STEPPING), which always get theirs. ``fitted``: the blocks of
    ramps fitted before (by segment, then axis), taken as they are.
    """
    ramp = batch.ramps != RAMP_CONSTANT
    steady = np.flatnonzero(~ramp)
    planned: dict[tuple[int, int], AxisSchedule] = {}
    if steady.size:  # checked in closed form, a fit only where the prediction strays
        some = SegmentBatch(batch.ticks[steady], batch.deltas[steady], batch.ramps[steady])
        part = plan_schedules(some, ctx.cycles_per_tick, tol_cycles, ctx.table)
        planned.update({(int(steady[j]), k): sched for (j, k), sched in part.items()})
    if needed is None:
        needed = np.zeros(len(batch), bool)
    start = time.perf_counter()
    fits = 0
    fitted = fitted or {}
    for i in np.flatnonzero(ramp).tolist():
        if i in fitted:
            continue
        spent = time.perf_counter() - start
        each = spent / fits if fits else RAMP_FIT_S  # what one more is likely to take
        if fit_budget_s is not None and spent + each > fit_budget_s and not needed[i]:
            continue
        fits += 1
        part = plan_schedules(batch[i : i + 1], ctx.cycles_per_tick, tol_cycles, ctx.table)
        planned.update({(i, k): sched for (_, k), sched in part.items()})
    if not planned:
        return {(i, k): s for i, axes in fitted.items() for k, s in axes.items()}
    budget = max_payload - SEGMENT_MAX_BYTES
    by_segment: dict[int, list[int]] = {}
    for i, k in planned:
        by_segment.setdefault(i, []).append(k)
    out: dict[tuple[int, int], AxisSchedule] = {}
    for i, axes in by_segment.items():
        ticks, deltas = int(batch.ticks[i]), tuple(int(v) for v in batch.deltas[i])
        ok = predictable(np.asarray(deltas), np.array(ticks), np.array(int(batch.ramps[i])))
        kept: dict[int, AxisSchedule] = {}
        for k in sorted(axes, key=lambda k: (not ok[k], k)):
            sched = planned[(i, k)]
            if len(sched.chunks) > MAX_CHUNKS:
                continue
            trial = {**kept, k: sched}
            if ok[k] or len(encode_block_for(ticks, deltas, trial, ctx)) <= budget:
                kept = trial  # a prediction that strays always has its (one-chunk) block
        out.update({(i, k): s for k, s in kept.items()})
    out.update({(i, k): s for i, axes in fitted.items() for k, s in axes.items()})
    return out


class SessionConfig(Protocol):
    """What the stream needs of the session set-up."""

    configured_rate: float
    start_ticks: int

    def configure(self) -> None: ...


class SegmentFeed:
    """The segment stream of one link (its core): ``feed``, ``queue_segments``."""

    def __init__(
        self, core: LinkCore, session: SessionConfig, renew: Callable[[], None] | None = None
    ):
        self.core = core
        self.session = session
        # the caller's keep-alive of its heater lease: a feed that plans schedule blocks
        # for many ramps (the fit runs in Python, milliseconds a ramp) is the job at work
        self.renew = renew or (lambda: None)
        self._began = time.perf_counter()
        self._fit_s = 0.0  # host time spent planning schedule blocks
        self.ring = RingRoom()  # the device's ring of block entries (3.2)
        # the blocks of ramps fitted and not sent (their ring had no room yet), by segment
        # of the batch they belong to: fitted once, sent later
        self._kept: tuple[SegmentBatch | None, dict[int, dict[int, AxisSchedule]]] = (None, {})

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
            c.flow.held_by_device()
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
        late = c.flow.late_worst_s
        room = c.flow.room_ticks(
            self.ahead_ticks(), rate, moving, self.session.start_ticks, now=c.t.now()
        )
        if c.flow.late_worst_s > late:
            low, high = c.flow.lead_s()
            if low > c.watermarks.low_s:
                log.info(
                    "%s: the host came %.3f s late to refill; keeping %.2f-%.2f s of motion ahead",
                    c.name,
                    c.flow.late_worst_s,
                    low,
                    high,
                )
        if room <= 0:
            return 0
        window = self._window_room()
        if window <= 0:
            return 0
        limit = min(len(ticks), slots, max(8, window // 2))
        cum = np.cumsum(ticks[:limit])
        return min(limit, int(np.searchsorted(cum, room, side="right")) + 1)

    def block_payload(self) -> int:
        """Payload bytes a segment with its schedule block may take: the line's frames, and
        up to a frame of BLOCK_FRAME_BYTES (within the device's longest), the size the plan
        cut its ramps for (block_cuts), while the line's frames are shorter only because
        they start short or the line lets such a frame through at least half the time: the
        segment then goes alone in a longer frame rather than without its block. On a
        line that loses more the block stays home and the device steps the ramp itself."""
        c = self.core
        return max(c.payload_limit, min(c.max_payload, BLOCK_FRAME_BYTES, c.payload_ceiling()))

    def _needs_block(self, batch: SegmentBatch) -> np.ndarray | None:
        """Per segment: faster at its peak than the device steps an axis without its
        schedule block (STEPPING, 3.1), so its ramp's block goes whatever the fit budget."""
        caps, ident = self.core.dev.caps, self.core.dev.identity
        if caps is None or caps.profile_step_rate is None or ident is None or not len(batch):
            return None
        peak = peak_step_rates(batch, ident.clock_hz).max(axis=1)
        return np.asarray(peak > caps.profile_step_rate)

    def _ring_needs(self, n: int, blocks: dict[tuple[int, int], AxisSchedule]) -> list[int]:
        """Entries each of the ``n`` segments' blocks takes in the device's ring (0: none);
        a block larger than the whole ring is left out (the device steps that ramp itself)."""
        needs = [0] * n
        for (i, _), sched in blocks.items():
            needs[i] += block_entries([len(sched.chunks)])
        ring = self.core.dev.ring
        if ring is not None:
            for i in [i for i, need in enumerate(needs) if need > ring.entries]:
                for key in [key for key in blocks if key[0] == i]:
                    del blocks[key]
                needs[i] = 0
        return needs

    def _send_segments(self, batch: SegmentBatch, i: int, j: int) -> int:
        """Send segments ``i..j`` of ``batch``, up to the first whose block the device's
        ring has no room for yet (3.2); returns how many went."""
        c = self.core
        sub = batch[i:j]
        budget = min(FIT_TURN_S, FIT_SHARE * (time.perf_counter() - self._began) - self._fit_s)
        kept = self._kept_for(batch)
        blocks = self._fit_blocks(
            sub,
            budget,
            self._needs_block(sub),
            {a - i: axes for a, axes in kept.items() if i <= a < j},
        )
        ring = c.dev.ring
        self.ring.follow(ring, c.ep.sender.items_after(ring.ack) if ring else 0)
        n = self.ring.admit(ring, self._ring_needs(j - i, blocks))
        later = {a: axes for a, axes in kept.items() if a >= j}  # (fitted, not in this turn)
        for (a, k), sched in blocks.items():
            if a >= n:
                later.setdefault(i + a, {})[k] = sched
        self._kept = (batch, later)
        if n == 0:
            return 0
        if n < j - i:
            sub = sub[:n]
            blocks = {key: s for key, s in blocks.items() if key[0] < n}
        data, offsets = encode_segments(sub, c.ctx, blocks)
        pos = 0
        limit = min(c.payload_limit, STREAM_FRAME_BYTES)
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
        return n

    def _kept_for(self, batch: SegmentBatch) -> dict[int, dict[int, AxisSchedule]]:
        """The blocks fitted and not sent yet, by segment of ``batch`` (none of another's)."""
        kept_batch, kept = self._kept
        return kept if kept_batch is batch else {}

    def _fit_blocks(
        self,
        sub: SegmentBatch,
        budget_s: float,
        needed: np.ndarray | None,
        fitted: Mapping[int, Mapping[int, AxisSchedule]] | None = None,
    ) -> dict[tuple[int, int], AxisSchedule]:
        """:func:`wire_schedules` for the device's tolerance and frames, its time counted."""
        c = self.core
        caps = c.dev.caps or DeviceCaps()
        now = time.perf_counter()
        blocks = wire_schedules(
            sub,
            c.ctx,
            caps.schedule_tolerance_cycles,
            self.block_payload(),
            fit_budget_s=budget_s,
            needed=needed,
            fitted=fitted,
        )
        self._fit_s += time.perf_counter() - now
        return blocks

    def _prefit(self, batch: SegmentBatch, i: int, n: int) -> None:
        """While the feed waits for room: the blocks of the next ramps that must carry one
        (STEPPING), fitted and kept as a send fits them, so the send does not wait on them."""
        kept = self._kept_for(batch)
        j = min(n, i + PREFIT_AHEAD)
        needed = self._needs_block(batch[i:j])
        if needed is None:
            return
        ramps = needed & (batch.ramps[i:j] != RAMP_CONSTANT)
        todo = [a for a in (np.flatnonzero(ramps) + i).tolist() if a not in kept][:PREFIT_RAMPS]
        if not todo:
            return
        idx = np.asarray(todo)
        some = SegmentBatch(batch.ticks[idx], batch.deltas[idx], batch.ramps[idx])
        blocks = self._fit_blocks(some, 0.0, np.ones(len(todo), bool))
        for a in todo:
            kept.setdefault(a, {})  # fitted, even where no axis keeps a block
        for (a, k), sched in blocks.items():
            kept[todo[a]][k] = sched
        self._kept = (batch, kept)

    def check_step_rates(self, batch: SegmentBatch, identity: Identity) -> None:
        """Raise :class:`StepRateError` for a segment over the device's max step rate, over
        the total its axes share (STEP_BUDGET), or shorter than the shortest one it takes
        (CAPS)."""
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
        total = caps.total_step_rate if caps is not None else None
        if total is not None:
            over = np.flatnonzero(rates.sum(axis=1) > total)
            if over.size:
                k = int(over[0])
                raise StepRateError(
                    f"segment {k} of the batch: its axes' peak step rates add up to "
                    f"{rates[k].sum():.0f}/s, over the device's total of {total}/s"
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
            keep_pauses_short()
            self.renew()
            with c.locked():
                if c.dev.failure is not None:
                    raise c.dev.failure
                k = self._sendable(batch.ticks[i:n])
                if k > 0:
                    ramps = np.cumsum(batch.ramps[i : i + k] != RAMP_CONSTANT)
                    most = RAMPS_PER_TURN
                    room = self.ring.blocks_room(c.dev.ring)
                    if room is not None:  # the ramps the ring takes, fitted in one turn
                        most = min(most, room)
                    k = max(1, int(np.searchsorted(ramps, most, side="right")))
                    sent = self._send_segments(batch, i, i + k)
                    i += sent
                    if sent:
                        continue
                    # the next block waits for room in the device's ring: for a report
                    if c.t.now() >= until:
                        break
                    if self.ring.head is None and c.ep.sender.idle():
                        # not known yet where the device's head is (its last report held
                        # frames not queued): ask for a report that counts them all
                        c.send_immediate(GetStatus())
                        c.write(c.ep.flush(c.t.now()))
                    self._prefit(batch, i, n)
                    c.pump(min(until - c.t.now(), 0.25))
                    continue
                now = c.t.now()
                if now >= until:
                    break
                wake = c.flow.wake_in(
                    self.ahead_ticks(), c.clock_rate(), bool(c.dev.flow.flags & Flag.MOVING), now
                )
                # below the low watermark already: only a report can give room
                wait = until - now if not wake else min(until - now, wake)
                self._prefit(batch, i, n)
                c.pump(min(wait, 0.25))
        return i
