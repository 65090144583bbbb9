"""Executed segment numbers -> the program: G-code line, layer, position, steps.

The device reports how many segments it has executed; the job keeps the batches
it queued (with their first segment number) until they are fully executed, so
memory stays bounded by the device queue, not the file.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from cdprhost.motion.segments import PlannedSegments


@dataclass(frozen=True)
class SegmentInfo:
    number: int
    line: int
    layer: int
    point: tuple[float, float, float]
    steps: tuple[int, int, int, int]
    t_end_s: float


class SegmentMap:
    def __init__(self) -> None:
        self._batches: deque[tuple[int, PlannedSegments]] = deque()
        self._last: SegmentInfo | None = None

    def add(self, first_number: int, batch: PlannedSegments) -> None:
        if len(batch):
            self._batches.append((first_number, batch))

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
        return SegmentInfo(
            first + i,
            int(batch.line[i]),
            int(batch.layer[i]),
            tuple(float(v) for v in batch.point[i]),
            tuple(int(v) for v in batch.steps_abs[i]),
            float(batch.t_end[i]),
        )


def first_rest_index(batch: PlannedSegments, start: int = 0) -> int | None:
    """Index of the first segment at or after ``start`` that ends with the machine at rest."""
    rest = np.flatnonzero(batch.v_end[start:] <= 1e-9)
    return None if rest.size == 0 else start + int(rest[0])
