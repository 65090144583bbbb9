"""How much the host may send now: slots of credit, and motion ahead kept between two
watermarks in time (PROTOCOL.md section 6). Pure bookkeeping, no I/O."""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware_protocol.messages import Flag

START_SHARE = 0.8  # start threshold / high watermark


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
    """Hysteresis between the watermarks on the motion the device holds ahead."""

    def __init__(self, marks: Watermarks):
        self.marks = marks
        self.filling = True

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
        self, ahead: float, rate: float, moving: bool = True, start_ticks: int = 0
    ) -> float:
        """Ticks that may be sent now (0 while above the low watermark after a refill).

        A device at rest starts only once it holds its start threshold, so while it is
        not moving the host fills at least that far, whatever the hysteresis says."""
        low, high = self.marks.low_s * rate, self.marks.high_s * rate
        if not moving:
            high = max(high, 1.05 * start_ticks)
        if ahead <= low or not moving:
            self.filling = True
        if ahead >= high:
            self.filling = False
        return max(0.0, high - ahead) if self.filling else 0.0

    def wake_in(self, ahead: float, rate: float, moving: bool) -> float | None:
        """Host seconds until the motion ahead falls to the low watermark (None: not draining)."""
        if not moving or rate <= 0:
            return None
        return max(0.0, (ahead - self.marks.low_s * rate) / rate)
