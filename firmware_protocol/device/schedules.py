"""What the simulated device checks of a segment's step schedules on receipt (PROTOCOL.md
5.5 and section 8): the block's schedules against their segment, every moving axis's
edges against their ideal times, the block's shortest interval against the device's.

A refusal is ``(axis, value)`` for ``ERROR BAD_VALUE``; nothing of the segment moves.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from firmware_protocol.ramp_profile import RAMP_CONSTANT
from firmware_protocol.schedule_block import ScheduleBlockError, check_block
from firmware_protocol.step_schedule import (
    FRAC_BITS,
    AxisSchedule,
    device_edges,
    ideal_edges,
    predictable_one,
    predicted_error_one,
    segment_schedules,
    shortest_interval,
)

I32_MAX = (1 << 31) - 1


def _clamp(v: int) -> int:
    return max(-I32_MAX, min(I32_MAX, int(v)))


def _block_refusal(sched: AxisSchedule, steps: int) -> int:
    """The value a block's axis is refused with (its first chunk's count when the counts
    are wrong, else the offending interval or first edge)."""
    first = sched.chunks[0] if sched.chunks else None
    if steps == 0 or first is None:
        return 0
    if not 1 <= first.count <= 0xFFFF:
        return first.count
    if sched.count != steps:  # (a block on the wire always counts |n|: its first takes the rest)
        return sched.count
    for c in sched.chunks:
        if not 1 <= c.count <= 0xFFFF:
            return c.count
        if c.interval < 1:
            return c.interval
    return sched.lead


def schedule_refusal(
    ticks: int,
    deltas: Sequence[int],
    ramp: int,
    explicit: Mapping[int, AxisSchedule],
    *,
    cycles_per_tick: int,
    tol_cycles: int,
    min_interval_cycles: int,
    table: np.ndarray,
) -> tuple[int, int] | None:
    """Why the device refuses the segment's schedules, as ``(axis, value)``; None: they
    run. ``explicit``: the block's schedules by axis. Checked in axis order, for each axis
    its block's form against the segment, its shortest interval, then its edges; a
    predicted axis whose closed-form bound is within the tolerance needs no edge check.
    An axis it cannot predict and the block leaves out runs on the device's own stepping
    of the profile (PROTOCOL.md 5.5: 3.0's fallback), exact in this model."""
    for axis in sorted(explicit):
        try:
            check_block({axis: explicit[axis]}, deltas)
        except ScheduleBlockError:
            return axis, _clamp(_block_refusal(explicit[axis], abs(int(deltas[axis]))))
        shortest = shortest_interval(explicit[axis])
        if shortest and shortest < min_interval_cycles << FRAC_BITS:
            return axis, shortest >> FRAC_BITS
    code = ramp if ramp >= 0 else RAMP_CONSTANT
    checked = [0, 0, 0, 0]
    for k in range(4):
        d = int(deltas[k])
        if k in explicit:
            continue
        if (
            predictable_one(d, ticks, code)
            and predicted_error_one(d, ticks, table, cycles_per_tick) > tol_cycles
        ):
            # predictable, but not within the tolerance in closed form: its edges are
            # checked (an axis it cannot predict, 3.0 until the host cuts every segment
            # whose block is too long, it steps along its own profile)
            checked[k] = d
    if not explicit and not any(checked):
        return None
    schedules = segment_schedules(np.array(checked), ticks, ramp, dict(explicit), table)
    end = ticks * cycles_per_tick
    for k, sched in sorted(schedules.items()):
        edges = device_edges(sched)
        ideal = ideal_edges(int(deltas[k]), ticks, ramp, cycles_per_tick)
        if edges[0] < 0 or edges[-1] >= end:
            return k, _clamp(int(edges[0] if edges[0] < 0 else edges[-1]))
        err = float(np.abs(edges - ideal).max())
        if err > tol_cycles:
            return k, _clamp(int(np.ceil(err)))
    return None
