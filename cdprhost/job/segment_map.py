"""Executed segment numbers -> the program: G-code line, layer, position, steps.

The device reports how many segments it has executed; the job keeps the batches
it queued (with their first segment number) until they are fully executed, so
memory stays bounded by the device queue, not the file.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from cdprhost.motion.segments import PlannedSegments


@dataclass(frozen=True)
class SegmentInfo:
    number: int
    line: int
    layer: int
    point: tuple[float, float, float]
    steps: tuple[int, int, int, int]
    t_end_s: float
    e_mm: float = 0.0  # filament position at the end, in the job's program


class SegmentMap:
    def __init__(self, clock_hz: int = 100_000) -> None:
        self.clock_hz = clock_hz
        self._batches: deque[tuple[int, PlannedSegments]] = deque()
        self._last: SegmentInfo | None = None
        self.start_s: float | None = None  # program time when the first segment began

    def add(self, first_number: int, batch: PlannedSegments) -> None:
        if len(batch):
            if self.start_s is None:
                self.start_s = float(batch.t_end[0]) - float(batch.ticks[0]) / self.clock_hz
            self._batches.append((first_number, batch))

    def drop_after(self, number: int) -> None:
        """Forget the segments after ``number`` (flushed from the device: sent again later)."""
        while self._batches and self._batches[-1][0] > number:
            self._batches.pop()
        if self._batches:
            first, batch = self._batches[-1]
            keep = number - first + 1
            if keep < len(batch):
                self._batches[-1] = (first, batch.take(slice(0, keep)))

    def lookup(self, number: int) -> SegmentInfo | None:
        """Info of segment ``number`` (1-based), dropping batches wholly before it."""
        if number <= 0:
            return self._last
        while self._batches and self._batches[0][0] + len(self._batches[0][1]) <= number:
            first, batch = self._batches.popleft()
            self._last = self._info(first, batch, len(batch) - 1)
        if not self._batches or number < self._batches[0][0]:
            return self._last
        first, batch = self._batches[0]
        return self._info(first, batch, number - first)

    @staticmethod
    def _info(first: int, batch: PlannedSegments, i: int) -> SegmentInfo:
        p, s = batch.point[i], batch.steps_abs[i]
        return SegmentInfo(
            first + i,
            int(batch.line[i]),
            int(batch.layer[i]),
            (float(p[0]), float(p[1]), float(p[2])),
            (int(s[0]), int(s[1]), int(s[2]), int(s[3])),
            float(batch.t_end[i]),
            float(batch.e[i]),
        )
