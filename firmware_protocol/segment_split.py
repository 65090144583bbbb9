"""Segments cut in two along their own profile, for schedules a block cannot carry.

A long ramp (from rest to a high rate over thousands of steps) can need more chunks on one
axis than a schedule block holds (``MAX_CHUNKS``): a quadratic in the step index follows a
constant acceleration's square root only so far. Such a segment is cut at a tick in two
segments of the same kind (PROTOCOL.md 5.1: a piece of a constant acceleration is one):
the first piece takes the steps the profile has issued by the cut (the device's own rule,
``floor(|n| p + 1/2)``), the second the rest; each piece's ramp code is its share of start
speed, so a ramp from rest still starts from rest and one to rest still ends there. The
joint-space path is the same straight line; the positions at the cut are whole steps, as at
every segment boundary.
"""

from __future__ import annotations

import numpy as np

from firmware_protocol.ramp_profile import (
    RAMP_CONSTANT,
    RAMP_FROM_REST,
    RAMP_TO_REST,
    ramp_share,
    steps_done,
)
from firmware_protocol.schedule_block import MAX_CHUNKS, encode_block
from firmware_protocol.schedule_fit import plan_schedules
from firmware_protocol.segments import SegmentBatch
from firmware_protocol.step_schedule import AxisSchedule, reciprocal_table

Piece = tuple[int, tuple[int, int, int, int], int]  # ticks, deltas, ramp code


def _code(v_start: float, v_end: float) -> int:
    total = v_start + v_end
    return RAMP_CONSTANT if total <= 0 else int(round(255.0 * v_start / total))


def split_segment(ticks: int, deltas: tuple[int, ...], code: int, at: int) -> tuple[Piece, Piece]:
    """The segment cut ``at`` ticks from its start (``0 < at < ticks``)."""
    if not 0 < at < ticks:
        raise ValueError(f"a cut at tick {at} of a {ticks}-tick segment: 1..{ticks - 1}")
    tau = at / ticks
    first = tuple(int(v) for v in steps_done(np.asarray(deltas), code, tau))
    second = tuple(int(d) - f for d, f in zip(deltas, first))
    if code == RAMP_CONSTANT:
        codes = (RAMP_CONSTANT, RAMP_CONSTANT)
    else:
        r = float(ramp_share(code))
        v0, v1, v2 = 2 * r, 2 * r + 2 * (1 - 2 * r) * tau, 2 - 2 * r  # speeds, in n / D
        codes = (_code(v0, v1), _code(v1, v2))
        if code == RAMP_FROM_REST:
            codes = (RAMP_FROM_REST, codes[1])
        if code == RAMP_TO_REST:
            codes = (codes[0], RAMP_TO_REST)
    a: Piece = (at, first, codes[0])  # type: ignore[assignment]
    b: Piece = (ticks - at, second, codes[1])  # type: ignore[assignment]
    return a, b


def _fitted_pieces(
    seg: Piece, cycles_per_tick: int, tol_cycles: float, table: np.ndarray
) -> list[tuple[Piece, dict[int, AxisSchedule]]]:
    """One segment, cut in halves until each piece's schedules fit a block."""
    t, d, c = seg
    one = SegmentBatch(np.array([t]), np.array([d]), np.array([c], dtype=np.int16))
    explicit = {
        k: s for (_, k), s in plan_schedules(one, cycles_per_tick, tol_cycles, table).items()
    }
    if all(len(s.chunks) <= MAX_CHUNKS for s in explicit.values()):
        return [(seg, explicit)]
    if t < 2:
        raise ValueError(f"a segment of {t} tick needs more than {MAX_CHUNKS} chunks")
    a, b = split_segment(t, d, c, t // 2)
    return _fitted_pieces(a, cycles_per_tick, tol_cycles, table) + _fitted_pieces(
        b, cycles_per_tick, tol_cycles, table
    )


def fit_for_blocks(
    batch: SegmentBatch, cycles_per_tick: int, tol_cycles: float, table: np.ndarray | None = None
) -> tuple[SegmentBatch, dict[tuple[int, int], AxisSchedule]]:
    """``batch`` with every segment whose schedules a block cannot carry cut in halves
    (again, until they can), and the explicit schedules of the result by ``(segment,
    axis)``, as :func:`schedule_fit.plan_schedules` gives them."""
    if table is None:
        table = reciprocal_table(cycles_per_tick)
    explicit = plan_schedules(batch, cycles_per_tick, tol_cycles, table)
    too_long = {i for (i, _), s in explicit.items() if len(s.chunks) > MAX_CHUNKS}
    if not too_long:
        return batch, explicit
    by_segment: dict[int, dict[int, AxisSchedule]] = {}
    for (i, k), sched in explicit.items():
        by_segment.setdefault(i, {})[k] = sched
    pieces: list[tuple[Piece, dict[int, AxisSchedule]]] = []
    for i in range(len(batch)):
        seg: Piece = (
            int(batch.ticks[i]),
            tuple(int(v) for v in batch.deltas[i]),  # type: ignore[assignment]
            int(batch.ramps[i]),
        )
        if i in too_long:
            pieces += _fitted_pieces(seg, cycles_per_tick, tol_cycles, table)
        else:
            pieces.append((seg, by_segment.get(i, {})))
    cut = SegmentBatch(
        np.array([p[0] for p, _ in pieces]),
        np.array([p[1] for p, _ in pieces]),
        np.array([p[2] for p, _ in pieces], dtype=np.int16),
    )
    out = {(j, k): s for j, (_, scheds) in enumerate(pieces) for k, s in scheds.items()}
    return cut, out


def block_sizes(
    batch: SegmentBatch, cycles_per_tick: int, tol_cycles: float, table: np.ndarray
) -> np.ndarray:
    """(n,) payload bytes of the schedule block each segment of ``batch`` needs (0: every
    moving axis runs the device's prediction; -1: one of its axes needs more chunks than a
    block holds, ``MAX_CHUNKS``). The batch's schedules are fitted together."""
    by_segment: dict[int, dict[int, AxisSchedule]] = {}
    for (i, k), sched in plan_schedules(batch, cycles_per_tick, tol_cycles, table).items():
        by_segment.setdefault(i, {})[k] = sched
    sizes = np.zeros(len(batch), np.int64)
    for i, scheds in by_segment.items():
        if any(len(s.chunks) > MAX_CHUNKS for s in scheds.values()):
            sizes[i] = -1
        else:
            deltas = tuple(int(v) for v in batch.deltas[i])
            sizes[i] = len(encode_block(deltas, int(batch.ticks[i]), scheds, table))
    return sizes
