"""How much the host may send now: slots of credit, and motion ahead kept between two
watermarks in time (PROTOCOL.md section 6). Pure bookkeeping, no I/O.

The watermarks a user sets are a floor, not a promise the host can keep on any PC: a host
that gets the CPU late (a busy print PC, a front end holding the interpreter, a long plan
between two batches) refills late, and the device runs dry if it is held up for longer
than the low watermark. So the flow measures its own lateness where it matters, at the
moment a refill falls due (how far below the low watermark the motion ahead had fallen
when the host came to send), and keeps the low watermark at :data:`LEAD_MARGIN` times the
worst lateness seen lately (it halves every :data:`LEAD_HALF_LIFE_S`), the high watermark
above it by the configured gap. A prompt host keeps the configured lead, and so the
configured response to a pause or an override; a starved one trades some of that
response for a device that does not run dry (Klipper keeps 1-2 s ahead for the same
reason)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_protocol.messages import Flag

START_SHARE = 0.8  # start threshold / high watermark
LEAD_MARGIN = 3.0  # the low watermark covers this many times the worst recent lateness
LEAD_HALF_LIFE_S = 120.0  # host seconds for the remembered lateness to halve
LEAD_MAX_LOW_S = 3.0  # the lateness never raises the low watermark past this (host s)


@dataclass(frozen=True)
class Watermarks:
    """Seconds (host time) of motion the device should hold ahead: refill at ``low_s``,
    up to ``high_s``. ``low_s`` must cover the worst retransmission and scheduling delay."""

    low_s: float = 0.5
    high_s: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low_s) and math.isfinite(self.high_s)):
            raise ValueError("watermarks must be finite")
        if not 0 < self.low_s < self.high_s <= 60:
            raise ValueError(f"need 0 < low ({self.low_s}) < high ({self.high_s}) <= 60 s")


@dataclass
class FlowReport:
    """The latest FLOW: counted after every frame before ``ack``; received at ``t``."""

    free: int = 0
    ack: int = 0
    buffered_ticks: int = 0
    flags: int = 0
    t: float = 0.0


class TimeFlow:
    """Hysteresis between the watermarks on the motion the device holds ahead, the
    watermarks raised while the host has been late to refill (see the module's text)."""

    def __init__(self, marks: Watermarks):
        self.marks = marks
        self.filling = True
        self.late_s = 0.0  # the worst refill lateness lately (decayed), host seconds
        self.late_worst_s = 0.0  # the worst ever seen by this flow
        self.low_max_s = marks.low_s  # the highest low watermark it kept
        self._late_at = 0.0  # when late_s was last decayed or raised
        self._held = False  # the device's slots held the host back since it last filled up
        self.refills = 0  # refills that fell due while the host waited for them
        self._due: float | None = None  # when the low watermark falls due, as last foreseen

    def lead_s(self, now: float | None = None) -> tuple[float, float]:
        """The (low, high) watermarks in force: the configured ones, raised to cover
        :data:`LEAD_MARGIN` times the recent lateness (at ``now``; None: as last updated)."""
        late = self.late_s
        if LEAD_MARGIN * late <= self.marks.low_s:  # (most of the time: the configured ones)
            return self.marks.low_s, self.marks.high_s
        if now is not None and now > self._late_at:
            late *= 0.5 ** ((now - self._late_at) / LEAD_HALF_LIFE_S)
        low = max(self.marks.low_s, min(LEAD_MAX_LOW_S, LEAD_MARGIN * late))
        return low, low + (self.marks.high_s - self.marks.low_s)

    def note_late(self, late_s: float, now: float) -> None:
        """The host came to refill ``late_s`` seconds after the low watermark was reached."""
        if now > self._late_at:
            self.late_s *= 0.5 ** ((now - self._late_at) / LEAD_HALF_LIFE_S)
            self._late_at = now
        self.late_s = max(self.late_s, late_s)
        self.late_worst_s = max(self.late_worst_s, late_s)
        self.low_max_s = max(self.low_max_s, self.lead_s(now)[0])

    @property
    def refill_due(self) -> float | None:
        """Host time at which the motion ahead is foreseen to reach the low watermark (None:
        not waiting for it)."""
        return self._due

    def held_by_device(self) -> None:
        """The device had no slot free: a refill that comes late now says nothing of the host."""
        self._held = True

    def ahead_ticks(
        self, report: FlowReport, now: float, rate: float, ticks_in_flight: int
    ) -> float:
        """Motion ahead of the device's now: what it reported, less what it has executed
        since (while moving), plus everything sent after the report's ACK."""
        held = float(report.buffered_ticks)
        if report.flags & Flag.MOVING:
            held -= rate * max(0.0, now - report.t)
        return max(0.0, held) + ticks_in_flight

    def start_ticks(self, rate: float) -> int:
        """The device's start threshold: most of the high watermark, so that a host whose
        rate estimate moves a little still sends enough to start the device."""
        return round(START_SHARE * self.marks.high_s * rate)

    def room_ticks(
        self,
        ahead: float,
        rate: float,
        moving: bool = True,
        start_ticks: int = 0,
        now: float | None = None,
    ) -> float:
        """Ticks that may be sent now (0 while above the low watermark after a refill).

        A device at rest starts only once it holds its start threshold, so while it is
        not moving the host fills at least that far, whatever the hysteresis says. With
        ``now`` (host seconds), a refill that comes below the low watermark counts as the
        host's lateness (only one that was waiting for it, the device's slots free all the
        while: a host already topping up, or held by the slots, is not late)."""
        low_s, high_s = self.lead_s(now)
        waiting = moving and not (self.filling or self._held) and rate > 0
        if waiting and now is not None and ahead <= low_s * rate:
            # a refill falls due: how late is the host to it? (the motion ahead stops at 0
            # when the device runs dry: then from when it was foreseen to fall due)
            late = low_s - ahead / rate
            if self._due is not None:
                late = max(late, now - self._due)
            self.note_late(late, now)
            self.refills += 1
            low_s, high_s = self.lead_s(now)
        low, high = low_s * rate, high_s * rate
        if not moving:
            high = max(high, 1.05 * start_ticks)
        if ahead <= low or not moving:
            self.filling = True
        if ahead >= high:
            self.filling = self._held = False
        waiting = moving and not (self.filling or self._held) and rate > 0
        self._due = now + (ahead - low) / rate if waiting and now is not None else None
        return max(0.0, high - ahead) if self.filling else 0.0

    def wake_in(
        self, ahead: float, rate: float, moving: bool, now: float | None = None
    ) -> float | None:
        """Host seconds until the motion ahead falls to the low watermark (None: not draining)."""
        if not moving or rate <= 0:
            return None
        return max(0.0, (ahead - self.lead_s(now)[0] * rate) / rate)
