"""What the simulated firmware checks of a segment's motion: on receipt the step rate, the
i32 range and the soft limits a host sets with ``SET_LIMITS``; during motion the limit
switch past the end of travel. PROTOCOL.md sections 4 and 8."""

from __future__ import annotations

import math
from collections.abc import Sequence

from firmware_protocol.codes import ALL_AXES, ErrorCode
from firmware_protocol.ramp_profile import ramp_share
from firmware_protocol.segments import MAX_DELTA, SEG_BASE


class SoftLimits:
    """Per-module inclusive step ranges (None: no limit), kept until the device resets."""

    def __init__(self) -> None:
        self.ranges: list[tuple[int, int] | None] = [None, None, None]

    def set(self, module: int, lo: int, hi: int) -> None:
        self.ranges[module] = (lo, hi)

    def violation(self, end: Sequence[int], homed: int) -> tuple[int, int] | None:
        """(module, position) of the first homed module whose ``end`` position lies
        outside its range; None when every one is inside. A segment's motion is monotonic
        on every axis, so its end decides."""
        for k, r in enumerate(self.ranges):
            if r is not None and homed >> k & 1 and not r[0] <= end[k] <= r[1]:
                return k, int(end[k])
        return None


def switch_crossing(
    physical: Sequence[int], deltas: Sequence[int], ramp: int, limit: int
) -> tuple[float, int, int] | None:
    """The limit switch ``limit`` steps past the homing switch: (tau, module, physical step)
    of the first step of the segment that reaches it, None if none does."""
    best = None
    r = float(ramp_share(ramp))
    for k in range(3):
        d = deltas[k]
        start = physical[k]
        if d > 0 and start <= limit < start + d:
            x = (limit + 1 - start - 0.5) / d  # normalised position of the offending step
            tau = x / (r + math.sqrt(r * r + (1 - 2 * r) * x))
            if best is None or tau < best[0]:
                best = (tau, k, limit + 1)
    return best


def segment_refusal(
    ticks: int,
    deltas: Sequence[int],
    ramp: int,
    tail: Sequence[int],
    *,
    homed: int,
    limits: SoftLimits,
    clock_hz: int,
    max_step_rate: int,
    scheduled: int = 0,
    total_step_rate: int | None = None,
) -> tuple[int, int, int] | None:
    """Why the device refuses a segment on receipt, as (ErrorCode, axis, value): a step rate
    over the limit, an end position outside i32, a homed module leaving its soft limits.
    ``tail``: where everything queued before it leaves the axes; ``scheduled``: the mask of
    the axes its schedule block carries (their schedule was checked instead of the rate,
    PROTOCOL.md 5.5); ``total_step_rate``: the budget the four axes share (STEP_BUDGET,
    3.3: their peak rates summed, the scheduled axes too; over it: ``STEP_RATE`` on axis
    4). None: accepted."""
    r = float(ramp_share(ramp))
    factor = max(2 * r, 2 - 2 * r) * clock_hz / ticks
    for axis, d in enumerate(deltas):
        if scheduled >> axis & 1:
            continue
        rate = abs(d) * factor
        if rate > max_step_rate * (1 + 1e-9):
            return ErrorCode.STEP_RATE, axis, int(rate)
    if total_step_rate:
        total = sum(abs(d) for d in deltas) * factor
        if total > total_step_rate * (1 + 1e-9):
            return ErrorCode.STEP_RATE, ALL_AXES, min(int(total), 0x7FFFFFFF)
    end = [p + d for p, d in zip(tail, deltas)]
    if any(abs(p) > MAX_DELTA for p in end):
        worst = max(range(4), key=lambda k: abs(end[k]))
        return ErrorCode.BAD_VALUE, SEG_BASE, max(-MAX_DELTA, min(MAX_DELTA, end[worst]))
    out = limits.violation(end, homed)
    if out is not None:
        return ErrorCode.ENDSTOP_HIT, out[0], out[1]
    return None
