"""Step schedules: each axis's step edges in a segment as a few add-only recurrences.

The step engine (docs/step-engine.md) issues every step edge from a per-axis recurrence in
CPU cycles, with no division per step: a segment's axis starts with its first edge at
``lead`` (from the segment's start) and runs a list of chunks ``(count, interval, add)``:

    for each chunk: I = interval; repeat count times: edge at T; T += I; I += add

``T``, ``interval`` and ``add`` are fixed point with ``FRAC_BITS`` fraction bits of a
cycle; an edge goes out at ``(T + HALF) >> FRAC_BITS`` cycles. The host chooses the
schedule (:func:`firmware_protocol.schedule_fit.fit_axis`) so that every edge lies within ``tol_cycles`` of its ideal time
on the segment's profile (PROTOCOL.md 5.1, :func:`firmware_protocol.ramp_profile.step_times`),
splitting an axis's steps into several chunks where one recurrence would stray further;
the counts add up to ``|n|`` exactly, so the record stays exact whatever the timing.
:func:`device_edges` is the device's arithmetic, integer for integer, which is what the
host checks against.

The device predicts the schedule of a constant-speed axis itself (:func:`predicted`): one
chunk, ``interval = 160 D / |n|`` cycles from a table of reciprocals (no division), the
first edge at half of it. :func:`firmware_protocol.schedule_fit.plan_schedules` checks that prediction for a whole batch at
once and fits a schedule only where it strays past the tolerance or cannot be made (ramps,
long segments): those are what the wire must carry.

Pure functions over numpy arrays; nothing here knows the wire yet.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_protocol.ramp_profile import RAMP_CONSTANT, ramp_share, step_times

CPU_HZ = 16_000_000
FRAC_BITS = 8
ONE = 1 << FRAC_BITS
HALF = ONE >> 1
MAX_COUNT = 0xFFFF  # a chunk's count is a u16
MAX_INTERVAL = (1 << 31) - 1  # fixed-point interval, u32 on the device (kept below 2**31)
PREDICT_MAX_STEPS = 1024  # the device's table of reciprocals: |n| up to this
PREDICT_MAX_TICKS = 0xFFFF  # and a duration that fits 16 bits (a 16 x 32-bit product)
RECIP_BITS = 16


@dataclass(frozen=True)
class Chunk:
    """``count`` edges; the first at the axis's current time, then ``interval`` and
    ``add`` (fixed point, ``FRAC_BITS``) as the recurrence says."""

    count: int
    interval: int
    add: int


@dataclass(frozen=True)
class AxisSchedule:
    """One axis's edges in one segment: the first at ``lead`` (fixed point, from the
    segment's start), then ``chunks`` in order."""

    lead: int
    chunks: tuple[Chunk, ...]

    @property
    def count(self) -> int:
        return sum(c.count for c in self.chunks)


def cycles_per_tick(clock_hz: int, cpu_hz: int = CPU_HZ) -> int:
    if cpu_hz % clock_hz:
        raise ValueError(f"the CPU clock {cpu_hz} Hz is not a whole multiple of {clock_hz} Hz")
    return cpu_hz // clock_hz


def ideal_edges(steps: int, ticks: int, code: int, cycles_per_tick: int) -> np.ndarray:
    """Each step's ideal time on the segment's profile, in cycles from its start (float)."""
    return step_times(steps, ticks, code) * float(cycles_per_tick)


def ideal_edges_many(
    steps: np.ndarray, ticks: np.ndarray, codes: np.ndarray, cycles_per_tick: int
) -> np.ndarray:
    """:func:`ideal_edges` of several axes (``steps`` > 0), one after another: the same
    arithmetic element for element, so the same floats."""
    steps = np.asarray(steps, dtype=np.int64)
    starts = np.cumsum(steps) - steps
    j = np.arange(int(steps.sum()), dtype=np.int64) - np.repeat(starts - 1, steps)
    x = (j - 0.5) / np.repeat(steps, steps)
    r = np.repeat(ramp_share(codes), steps)
    tau = x / (r + np.sqrt(r * r + (1.0 - 2.0 * r) * x))
    edges = tau * np.repeat(np.asarray(ticks, dtype=np.int64), steps) * float(cycles_per_tick)
    return np.asarray(edges, dtype=np.float64)


def device_times(schedule: AxisSchedule) -> np.ndarray:
    """The edges' times before rounding (fixed point, from the segment's start): exactly
    the device's integer recurrence (int64)."""
    if not schedule.chunks:
        return np.zeros(0, dtype=np.int64)
    times = []
    t = schedule.lead
    for c in schedule.chunks:
        k = np.arange(c.count, dtype=np.int64)
        times.append(t + k * c.interval + c.add * (k * (k - 1) // 2))
        t = t + c.count * c.interval + c.add * (c.count * (c.count - 1) // 2)
    return np.concatenate(times)


def device_edges(schedule: AxisSchedule) -> np.ndarray:
    """The edges the device issues for ``schedule``, in whole cycles from the segment's
    start (its fixed-point times rounded)."""
    return (device_times(schedule) + HALF) >> FRAC_BITS


def reciprocal_table(cycles_per_tick: int) -> np.ndarray:
    """The device's table: entry ``n`` (1..PREDICT_MAX_STEPS; entry 0 unused) is
    ``cycles_per_tick 2**(FRAC_BITS + RECIP_BITS) / n`` rounded (u32)."""
    n = np.arange(1, PREDICT_MAX_STEPS + 1, dtype=np.int64)
    num = cycles_per_tick << (FRAC_BITS + RECIP_BITS)
    table = np.zeros(PREDICT_MAX_STEPS + 1, dtype=np.int64)
    table[1:] = (2 * num + n) // (2 * n)
    if table[1] >= 1 << 32:
        raise ValueError(f"{cycles_per_tick} cycles a tick: the table's entries overflow 32 bits")
    return table


def predictable(steps: np.ndarray, ticks: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """Where the device predicts the schedule: constant speed, ``1 <= |n| <=
    PREDICT_MAX_STEPS``, ``D <= PREDICT_MAX_TICKS`` (arrays broadcast)."""
    n = np.abs(np.asarray(steps, dtype=np.int64))
    ok = (
        (np.asarray(codes) == RAMP_CONSTANT)
        & (n >= 1)
        & (n <= PREDICT_MAX_STEPS)
        & (np.asarray(ticks, dtype=np.int64) <= PREDICT_MAX_TICKS)
    )
    return np.asarray(ok, dtype=bool)


def predictable_one(steps: int, ticks: int, code: int) -> bool:
    """:func:`predictable` of one axis, in Python's numbers (the device model asks it of
    every received segment's axes)."""
    return (
        code == RAMP_CONSTANT
        and 1 <= abs(steps) <= PREDICT_MAX_STEPS
        and ticks <= PREDICT_MAX_TICKS
    )


def predicted_interval(steps: np.ndarray, ticks: np.ndarray, table: np.ndarray) -> np.ndarray:
    """The device's interval for a predictable axis: ``(D table[|n|] + 2**15) >> 16``."""
    n = np.abs(np.asarray(steps, dtype=np.int64))
    d = np.asarray(ticks, dtype=np.int64)
    scaled = d * table[np.minimum(n, PREDICT_MAX_STEPS)] + (1 << (RECIP_BITS - 1))
    return np.asarray(scaled >> RECIP_BITS, dtype=np.int64)


def predicted(steps: int, ticks: int, table: np.ndarray) -> AxisSchedule:
    """The schedule the device runs for a predictable axis when the wire carries none."""
    interval = int(predicted_interval(np.array(steps), np.array(ticks), table))
    return AxisSchedule(interval >> 1, (Chunk(abs(int(steps)), interval, 0),))


def predicted_error(
    steps: np.ndarray, ticks: np.ndarray, table: np.ndarray, cycles_per_tick: int
) -> np.ndarray:
    """A bound on the worst edge error (cycles) of each predicted schedule, in closed form:
    the device's edges before rounding and the ideal ones both lie on a line in the step
    index, so their distance is largest at the first or the last edge; rounding to whole
    cycles adds at most half a cycle."""
    n = np.abs(np.asarray(steps, dtype=np.int64))
    d = np.asarray(ticks, dtype=np.int64)
    interval = predicted_interval(n, d, table)
    lead = interval >> 1
    last = np.maximum(n - 1, 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        true = np.where(n > 0, d * cycles_per_tick / np.maximum(n, 1), 0.0)
    first_err = lead / ONE - 0.5 * true
    last_err = (lead + last * interval) / ONE - (last + 0.5) * true
    return np.asarray(np.maximum(np.abs(first_err), np.abs(last_err)) + 0.5, dtype=np.float64)


def predicted_error_one(steps: int, ticks: int, table: np.ndarray, cycles_per_tick: int) -> float:
    """:func:`predicted_error` of one predictable axis (``1 <= |steps| <= PREDICT_MAX_STEPS``)
    in Python's integers and floats: the same operations in the same order, so the same
    float, without an array's overhead (the device model checks every received segment's
    four axes with it)."""
    n = abs(steps)
    interval = (ticks * int(table[n]) + (1 << (RECIP_BITS - 1))) >> RECIP_BITS
    lead = interval >> 1
    last = n - 1
    true = ticks * cycles_per_tick / n
    first_err = lead / ONE - 0.5 * true
    last_err = (lead + last * interval) / ONE - (last + 0.5) * true
    return max(abs(first_err), abs(last_err)) + 0.5


def schedule_error(schedule: AxisSchedule, ideal: np.ndarray) -> np.ndarray:
    """Each device edge's distance from its ideal time, in cycles (signed: late > 0)."""
    edges = device_edges(schedule)
    if len(edges) != len(ideal):
        raise ValueError(f"the schedule issues {len(edges)} edges for {len(ideal)} steps")
    return np.asarray(edges - ideal, dtype=np.float64)


class ScheduleError(ValueError):
    """A segment's schedules that a device must refuse."""


def segment_schedules(
    deltas: np.ndarray,
    ticks: int,
    code: int,
    explicit: dict[int, AxisSchedule],
    table: np.ndarray,
) -> dict[int, AxisSchedule]:
    """Every moving axis's schedule as the device runs it: the one the wire carried, else
    its prediction. An axis the device cannot predict and the wire left out is refused."""
    out: dict[int, AxisSchedule] = {}
    for k, n in enumerate(int(d) for d in deltas):
        if k in explicit:
            out[k] = explicit[k]
        elif n:
            if not predictable_one(n, ticks, code):
                raise ScheduleError(f"axis {k}: {abs(n)} steps with no schedule to run them")
            out[k] = predicted(n, ticks, table)
    return out


def shortest_interval(schedule: AxisSchedule) -> int:
    """The shortest interval between two consecutive edges (fixed point; 0 for a single
    edge), in O(chunks) as the device checks it on receipt: a chunk's intervals change
    linearly, so the shortest is at one of its ends (its last one leads to the next
    chunk's first edge; the last chunk's last interval leads nowhere)."""
    shortest = 0
    last = len(schedule.chunks) - 1
    for i, c in enumerate(schedule.chunks):
        used = c.count if i < last else c.count - 1  # intervals between its edges and on
        if used < 1:
            continue
        ends = min(c.interval, c.interval + (used - 1) * c.add)
        shortest = ends if not shortest else min(shortest, ends)
    return shortest


def check_segment(
    deltas: np.ndarray,
    ticks: int,
    code: int,
    explicit: dict[int, AxisSchedule],
    cycles_per_tick: int,
    tol_cycles: float,
    table: np.ndarray,
) -> float:
    """What a device checks of a segment's schedules before it queues the segment: each
    moving axis has one, its counts are ``|n|``, every edge lies inside the segment and
    within ``tol_cycles`` of its ideal time. Returns the worst error in cycles; raises
    :class:`ScheduleError` naming the axis and the reason."""
    worst = 0.0
    for k, sched in segment_schedules(deltas, ticks, code, explicit, table).items():
        n = int(deltas[k])
        if sched.count != abs(n):
            raise ScheduleError(f"axis {k}: the schedule issues {sched.count} of {abs(n)} steps")
        edges = device_edges(sched)
        if edges[0] < 0 or edges[-1] >= ticks * cycles_per_tick:
            raise ScheduleError(f"axis {k}: an edge falls outside the segment")
        err = float(np.abs(edges - ideal_edges(n, ticks, code, cycles_per_tick)).max())
        if err > tol_cycles:
            raise ScheduleError(
                f"axis {k}: an edge {err:.1f} cycles from its time (tolerance {tol_cycles:g})"
            )
        worst = max(worst, err)
    return worst
