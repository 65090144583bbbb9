"""A deterministic demonstration stream of move segments (tests, demos, soak runs)."""

from __future__ import annotations

from typing import Any

import numpy as np

from firmware_protocol.ramp_profile import RAMP_CONSTANT, RAMP_TO_REST
from firmware_protocol.segments import SegmentBatch


def demo_stream(
    n: int, seed: int = 0, *, clock_hz: int = 100_000, min_ticks: int = 1000, max_ticks: int = 5000
) -> SegmentBatch:
    """``n`` segments of a smooth, bounded joint-space motion (sliders within +-8000 steps
    of the start, the extruder always feeding); the last segment ends at rest."""
    rng = np.random.default_rng(seed)
    ticks = rng.integers(min_ticks, max_ticks + 1, n)
    t = np.concatenate([[0], np.cumsum(ticks)]) / clock_hz
    freq = rng.uniform(0.05, 0.3, 3)
    phase = rng.uniform(0, 2 * np.pi, 3)
    sliders = 4000.0 * (np.sin(2 * np.pi * freq * t[:, None] + phase) - np.sin(phase))
    extruder = 30.0 * t[:, None]
    pos = np.rint(np.hstack([sliders, extruder])).astype(np.int64)
    ramps = np.full(n, RAMP_CONSTANT, dtype=np.int16)
    if n:
        ramps[-1] = RAMP_TO_REST
    return SegmentBatch(ticks, np.diff(pos, axis=0), ramps)


def expected_record(
    batch: SegmentBatch,
    *,
    clock_hz: int = 100_000,
    start: tuple[int, int, int, int] = (0, 0, 0, 0),
    first_seq: int = 1,
    start_ticks: int = 0,
) -> list[dict[str, Any]]:
    """The record a device must produce executing ``batch`` from ``start`` (see device/record.py)."""
    steps = np.asarray(start, dtype=np.int64) + np.cumsum(batch.deltas, axis=0)
    ticks = start_ticks + np.cumsum(batch.ticks)
    return [
        {
            "seq": first_seq + i,
            "steps": [int(v) for v in steps[i]],
            "t": round(int(ticks[i]) / clock_hz, 6),
        }
        for i in range(len(batch))
    ]
