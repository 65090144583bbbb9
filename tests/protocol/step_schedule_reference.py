"""The first fitter of firmware_protocol/step_schedule.py, kept as the reference the
vectorised one is tested (tests/protocol/test_step_schedule.py) and timed
(bench/step_schedule.py) against: one chunk at a time, each candidate count fitted and
checked on its own (numpy over one chunk's edges, a Python loop over the search)."""

from __future__ import annotations

import numpy as np

from firmware_protocol.segments import SegmentBatch
from firmware_protocol.step_schedule import (
    FRAC_BITS,
    HALF,
    MAX_COUNT,
    ONE,
    AxisSchedule,
    Chunk,
    ideal_edges,
    predictable,
    predicted_error,
    reciprocal_table,
)

_K = np.arange(1, MAX_COUNT + 2, dtype=np.float64)
_TRI = _K * (_K - 1) / 2.0


def _fit(offsets: np.ndarray, n_fit: int) -> tuple[int, int]:
    """Least-squares ``interval, add`` from 0 through ``offsets[k-1]`` at step k."""
    if n_fit <= 0:
        return 0, 0
    y = offsets[:n_fit]
    if n_fit == 1:
        return int(round(y[0] * ONE)), 0
    m = float(n_fit)
    s2 = m * (m + 1) * (2 * m + 1) / 6
    s3 = (m * (m + 1) / 2) ** 2
    s4 = m * (m + 1) * (2 * m + 1) * (3 * m * m + 3 * m - 1) / 30
    a11, a12, a22 = s2, (s3 - s2) / 2, (s4 - 2 * s3 + s2) / 4
    b1 = float(np.dot(_K[:n_fit], y))
    b2 = float(np.dot(_TRI[:n_fit], y))
    det = a11 * a22 - a12 * a12
    i_fit = (b1 * a22 - b2 * a12) / det
    a_fit = (a11 * b2 - a12 * b1) / det
    return int(round(i_fit * ONE)), int(round(a_fit * ONE))


def _chunk_error(t0: int, ideal: np.ndarray, start: int, count: int, chunk: Chunk) -> float:
    k = np.arange(count + 1, dtype=np.int64)
    fixed = t0 + k * chunk.interval + chunk.add * (k * (k - 1) // 2)
    edges = (fixed + HALF) >> FRAC_BITS
    stop = min(start + count + 1, len(ideal))
    return float(np.max(np.abs(edges[: stop - start] - ideal[start:stop])))


def _chunk_at(t0: int, ideal: np.ndarray, start: int, count: int) -> Chunk:
    base = t0 / ONE
    last = start + count + 1 <= len(ideal)
    n_fit = count if last else count - 1
    interval, add = _fit(ideal[start + 1 : start + 1 + n_fit] - base, n_fit)
    return Chunk(count, max(interval, 1), add)


def _longest_chunk(t0: int, ideal: np.ndarray, start: int, tol_cycles: float, hint: int) -> Chunk:
    limit = min(len(ideal) - start, MAX_COUNT)

    def ok(count: int) -> tuple[bool, Chunk]:
        chunk = _chunk_at(t0, ideal, start, count)
        return _chunk_error(t0, ideal, start, count, chunk) <= tol_cycles, chunk

    lo, best = 1, ok(1)[1]
    hi = max(2, min(hint, limit))
    while hi <= limit:
        fits, chunk = ok(hi)
        if not fits:
            break
        lo, best = hi, chunk
        hi *= 2
    hi = min(hi, limit + 1)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        fits, chunk = ok(mid)
        if fits:
            lo, best = mid, chunk
        else:
            hi = mid
    return best


def reference_fit_axis(ideal: np.ndarray, tol_cycles: float) -> AxisSchedule:
    """The first ``fit_axis``: the same contract, one chunk's search at a time."""
    n = len(ideal)
    if n == 0:
        return AxisSchedule(0, ())
    lead = int(round(float(ideal[0]) * ONE))
    chunks: list[Chunk] = []
    t = lead
    start = 0
    while start < n:
        best = _longest_chunk(t, ideal, start, tol_cycles, chunks[-1].count if chunks else 1)
        chunks.append(best)
        t = t + best.count * best.interval + best.add * (best.count * (best.count - 1) // 2)
        start += best.count
    return AxisSchedule(lead, tuple(chunks))


def reference_plan_schedules(
    batch: SegmentBatch, cycles_per_tick: int, tol_cycles: float, table: np.ndarray | None = None
) -> dict[tuple[int, int], AxisSchedule]:
    """The first ``plan_schedules``: the same check of the predictions, then each axis the
    wire must carry fitted on its own by :func:`reference_fit_axis`."""
    if table is None:
        table = reciprocal_table(cycles_per_tick)
    n = batch.deltas
    codes = np.broadcast_to(batch.ramps[:, None], n.shape)
    ticks = np.broadcast_to(batch.ticks[:, None], n.shape)
    ok = predictable(n, ticks, codes)
    ok[ok] = predicted_error(n[ok], ticks[ok], table, cycles_per_tick) <= tol_cycles
    explicit = {}
    for i, k in zip(*np.nonzero((n != 0) & ~ok)):
        ideal = ideal_edges(int(n[i, k]), int(batch.ticks[i]), int(batch.ramps[i]), cycles_per_tick)
        explicit[(int(i), int(k))] = reference_fit_axis(ideal, tol_cycles)
    return explicit
