"""The host's fitter of step schedules: each axis the device cannot predict, as few
add-only chunks as a greedy search finds, every edge within tolerance of its ideal time.

The schedules, the device's arithmetic, its prediction and its checks are
:mod:`firmware_protocol.step_schedule`; this module only chooses schedules.
:func:`plan_schedules` checks a whole batch's predictions at once and fits what strays or
cannot be predicted (ramps, long segments): what the wire must carry.
"""

from __future__ import annotations

from itertools import chain

import numpy as np

from firmware_protocol.segments import SegmentBatch
from firmware_protocol.step_schedule import (
    FRAC_BITS,
    HALF,
    MAX_COUNT,
    ONE,
    AxisSchedule,
    Chunk,
    ideal_edges_many,
    predictable,
    predicted_error,
    reciprocal_table,
)

# The fitter. An axis's chunks are found greedily, one after another: from the edge where
# the last chunk left off (placed where its recurrence put it), the longest count whose
# least-squares recurrence keeps every edge within tolerance, searched by doubling from the
# last chunk's count and then bisecting. The search runs for many axes at once (every
# explicit axis of a batch): each round, every axis still fitting names the counts its
# search may try next, and all of them are fitted and checked together in one pass of
# numpy over their edges (:func:`_try_counts`). An axis names several counts a round (the
# whole range a short search can still reach, or a few levels of a long bisection), so
# that one round usually settles a chunk, and a batch takes about as many rounds as its
# longest axis has chunks. Each search is then replayed over what it has tried, so the
# result is that of trying one count at a time: in Python for a few axes (:func:`_seek`),
# in numpy for many (:func:`_advance_many`), where a Python loop over the axes would cost
# more than the numpy.

_ROUND_EDGES = 2048  # edges a round tries, shared among the axes still fitting
_AXIS_EDGES = 64  # but at least this many an axis


def _normal_equations(top: int) -> tuple[np.ndarray, ...]:
    """For m = 0..top fitted edges: the normal equations' matrix ``a11, a12, a22`` of the
    least squares on ``k I + k (k - 1) / 2 a`` (k = 1..m) and its determinant. Below two
    edges the system is singular; its rows there make the solution ``I = b1, a = 0``
    (one edge met exactly with no add, or none and any interval)."""
    m = np.arange(top + 1, dtype=np.float64)
    s2 = m * (m + 1) * (2 * m + 1) / 6
    s3 = (m * (m + 1) / 2) ** 2
    s4 = m * (m + 1) * (2 * m + 1) * (3 * m * m + 3 * m - 1) / 30
    a11, a12, a22 = s2, (s3 - s2) / 2, (s4 - 2 * s3 + s2) / 4
    det = a11 * a22 - a12 * a12
    a11[:2], a12[:2], a22[:2], det[:2] = 0.0, 0.0, 1.0, 1.0
    return a11, a12, a22, det


_A11, _A12, _A22, _DET = _normal_equations(MAX_COUNT)
_TRI = np.arange(MAX_COUNT + 1, dtype=np.int64) * np.arange(-1, MAX_COUNT, dtype=np.int64) // 2


def _try_counts(
    ideal: np.ndarray,
    axes: np.ndarray,
    tried: list[int] | np.ndarray,
    counts: np.ndarray,
    tol_cycles: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidate chunks of several axes: row 0 of ``axes`` is each axis's next edge in the
    flat ``ideal``, row 1 how many edges remain in the axis from there, row 2 that edge's
    time (fixed point); the axis tries ``tried`` of the ``counts``, one after another. A
    candidate's chunk runs ``count`` edges from that edge: returns whether every one of them
    (and the next one it sets up, when there is one) lies within ``tol_cycles``, and its
    ``interval, add``: least squares on ``k I + k (k - 1) / 2 a`` through its edges after
    the first (k = 1..), by the normal equations. One pass of numpy over all the edges."""
    first, left, t0 = np.repeat(axes, tried, axis=1)
    size = np.minimum(counts + 1, left)  # the chunk's edges and the next, if any
    starts = np.cumsum(size) - size
    each = np.repeat(np.array([starts, first - starts, t0]), size, axis=1)
    run = np.arange(each.shape[1], dtype=np.int64)
    k = run - each[0]  # the edge's index in its chunk
    at = ideal[each[1] + run]
    tri = _TRI[k]
    y = at - each[2] / ONE
    b1 = np.add.reduceat(k * y, starts)
    b2 = np.add.reduceat(tri * y, starts)
    m = size - 1  # edges fitted
    a12, det = _A12[m], _DET[m]
    interval = np.maximum(np.rint((b1 * _A22[m] - b2 * a12) / det * ONE).astype(np.int64), 1)
    add = np.rint((_A11[m] * b2 - a12 * b1) / det * ONE).astype(np.int64)
    step = np.repeat(np.array([interval, add]), size, axis=1)
    fixed = each[2] + k * step[0] + step[1] * tri
    err = np.abs(((fixed + HALF) >> FRAC_BITS) - at)
    ok = np.maximum.reduceat(err, starts) <= tol_cycles
    return ok, interval, add


def _midpoints(lo: int, hi: int, depth: int, out: list[int]) -> list[int]:
    """The counts a bisection of ``(lo, hi)`` may try in its next ``depth`` levels."""
    if depth and hi - lo > 1:
        mid = (lo + hi) // 2
        out.append(mid)
        _midpoints(lo, mid, depth - 1, out)
        _midpoints(mid, hi, depth - 1, out)
    return out


def _cost(lo: int, top: int) -> int:
    """Edges tried for every count in ``lo + 1 .. top``."""
    return (top - lo) * (top + lo + 3) // 2


def _ahead(lo: int, hi: int, limit: int, growing: bool, budget: int) -> list[int]:
    """What the search may try next from ``lo`` (fits) and ``hi``, within about ``budget``
    edges: when ``growing``, ``hi`` is the count it doubles to next and the range to try
    whole reaches as many doublings beyond it as the budget allows; else ``hi`` is the upper
    end of its bisection, tried whole or a few levels deep."""
    if growing:
        if hi > limit:
            return []
        top = min(2 * hi, limit)
        if _cost(lo, top) <= budget:
            while top < limit and _cost(lo, min(2 * top, limit)) <= budget:
                top = min(2 * top, limit)
            return list(range(lo + 1, top + 1))
        grown = [c for c in (hi, 2 * hi, 4 * hi) if c <= limit]
        return grown + _midpoints(lo, hi, max(1, (budget // hi).bit_length() - 1), [])
    if _cost(lo, hi - 1) <= budget:
        return list(range(lo + 1, hi))
    return _midpoints(lo, hi, max(1, (budget // hi).bit_length()), [])


def _seek(
    tried: dict[int, tuple[bool, int, int]], limit: int, hint: int, budget: int
) -> tuple[int, list[int]]:
    """Replays one chunk's search over the counts ``tried`` (count -> fits, interval, add):
    from ``hint`` (the last chunk's count: along a ramp they change slowly) grown by
    doubling while it fits, then bisected; a count of 1 always fits (its edge is the one the
    last chunk placed, and the next is fitted exactly). Returns the chunk's count, or 0 and
    the counts to try next."""
    lo, hi = 1, max(2, min(hint, limit))
    if 1 not in tried:
        return 0, [1, *_ahead(lo, hi, limit, True, budget)]
    while hi <= limit:
        got = tried.get(hi)
        if got is None:
            return 0, [c for c in _ahead(lo, hi, limit, True, budget) if c not in tried]
        if not got[0]:
            break
        lo, hi = hi, 2 * hi
    hi = min(hi, limit + 1)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        got = tried.get(mid)
        if got is None:
            return 0, [c for c in _ahead(lo, hi, limit, False, budget) if c not in tried]
        if got[0]:
            lo = mid
        else:
            hi = mid
    return lo, []


_FEW_AXES = 24  # more axes than this still fitting: their searches are replayed in numpy too
_GROWN = 2  # a round tries the next two doublings of a growing search
_LEVELS = 2  # and two levels of each bisection it may come to


def _subtree(lo: np.ndarray, hi: np.ndarray, levels: int) -> list[np.ndarray]:
    """The counts (0: none) a bisection of each ``(lo, hi)`` tries in its next ``levels``."""
    out = []
    spans = [(lo, hi)]
    for _ in range(levels):
        below = []
        for a, b in spans:
            mid = (a + b) >> 1
            out.append(np.where(b - a > 1, mid, 0))
            below += [(a, mid), (mid, b)]
        spans = below
    return out


def _advance_many(
    ideal: np.ndarray,
    firsts: list[int],
    lengths: list[int],
    t: list[int],
    start: list[int],
    hint: list[int],
    chunks: list[list[Chunk]],
    tol_cycles: float,
) -> None:
    """The searches of many axes advanced in numpy, their replay too, while more than
    ``_FEW_AXES`` are still fitting (``t``, ``start``, ``hint`` and ``chunks`` are brought
    up to date: the rest goes on from there). Each round every axis tries a count of 1 if
    its chunk is new (the chunk it keeps if nothing longer fits), the next doublings of its
    search and a few levels of the bisections it may come to; then each search is replayed
    as far as what it tried reaches."""
    first = np.array(firsts, dtype=np.int64)
    n = np.array(lengths, dtype=np.int64)
    s = np.array(start, dtype=np.int64)
    tt = np.array(t, dtype=np.int64)
    h = np.array(hint, dtype=np.int64)
    lo = np.ones(len(n), dtype=np.int64)
    hi = np.maximum(2, np.minimum(h, np.minimum(n - s, MAX_COUNT)))
    growing = np.ones(len(n), dtype=bool)
    fresh = np.ones(len(n), dtype=bool)  # the chunk's count of 1 not tried yet
    best = np.zeros((2, len(n)), dtype=np.int64)  # interval, add of the count lo
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    while np.count_nonzero(s < n) > _FEW_AXES:
        idx = np.flatnonzero(s < n)
        limit = np.minimum(n[idx] - s[idx], MAX_COUNT)
        a, b, g = lo[idx], hi[idx], growing[idx]
        top = np.minimum(b, limit + 1)
        cols = [np.where(fresh[idx], 1, 0)]
        cols += [np.where(g & (b << j <= limit), b << j, 0) for j in range(_GROWN)]
        cols += _subtree(a, np.where(g, top, b), _LEVELS)
        cols += _subtree(np.where(g, b, 0), np.where(g, np.minimum(2 * b, limit + 1), 0), _LEVELS)
        cand = np.stack(cols, axis=1)
        rows, slots = np.nonzero(cand)
        lanes = idx[rows]
        ok, steps, adds = _try_counts(
            ideal,
            np.array([first[lanes] + s[lanes], n[lanes] - s[lanes], tt[lanes]]),
            np.ones(len(rows), dtype=np.int64),
            cand[rows, slots],
            tol_cycles,
        )
        fits = np.zeros(cand.shape, dtype=bool)
        fits[rows, slots] = ok
        step = np.zeros(cand.shape, dtype=np.int64)
        step[rows, slots] = steps
        add = np.zeros(cand.shape, dtype=np.int64)
        add[rows, slots] = adds
        bi, ba = best[0, idx], best[1, idx]
        f = fresh[idx]
        bi[f], ba[f] = step[f, 0], add[f, 0]
        stuck = np.zeros(len(idx), dtype=bool)
        every = np.arange(len(idx))
        while True:
            over = g & (b > limit)  # grown past the axis: bisect up to its end
            b[over], g[over] = limit[over] + 1, False
            want = np.where(g, b, (a + b) >> 1)
            match = cand == want[:, None]
            slot = match.argmax(axis=1)
            live = ~stuck & (g | (b - a > 1))
            stuck |= live & ~match[every, slot]
            go = np.flatnonzero(live & ~stuck)
            if not len(go):
                break
            yes = fits[go, slot[go]]
            up, down = go[yes], go[~yes]
            a[up] = want[up]
            bi[up], ba[up] = step[up, slot[up]], add[up, slot[up]]
            b[up[g[up]]] *= 2
            g[down] = False
            b[down] = want[down]
        lo[idx], hi[idx], growing[idx], fresh[idx] = a, b, g, False
        best[0, idx], best[1, idx] = bi, ba
        done = ~g & (b - a <= 1)
        if not done.any():
            continue
        d = idx[done]
        count, di, da = a[done], bi[done], ba[done]
        found.append((d, count, di, da))
        tt[d] += count * di + da * (count * (count - 1) // 2)
        s[d] += count
        h[d] = count
        lo[d], growing[d], fresh[d] = 1, True, True
        hi[d] = np.maximum(2, np.minimum(count, np.minimum(n[d] - s[d], MAX_COUNT)))
    for d, count, di, da in found:
        for i, c, step_i, add_i in zip(d.tolist(), count.tolist(), di.tolist(), da.tolist()):
            chunks[i].append(Chunk(c, step_i, add_i))
    t[:], start[:], hint[:] = tt.tolist(), s.tolist(), h.tolist()


def _fit_axes(ideal: np.ndarray, lengths: list[int], tol_cycles: float) -> list[AxisSchedule]:
    """The schedules of several axes, whose ideal edges lie one after another in ``ideal``
    (``lengths`` of them each), every search advanced together."""
    if tol_cycles < 1:
        raise ValueError(f"tolerance {tol_cycles} cycles: at least 1 (edges are whole cycles)")
    firsts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64).tolist()
    leads = [int(round(float(ideal[f]) * ONE)) if n else 0 for f, n in zip(firsts, lengths)]
    chunks: list[list[Chunk]] = [[] for _ in lengths]
    start = [0] * len(lengths)
    t = list(leads)
    hint = [1] * len(lengths)
    if sum(1 for n in lengths if n) > _FEW_AXES:
        _advance_many(ideal, firsts, lengths, t, start, hint, chunks, tol_cycles)
    tried: list[dict[int, tuple[bool, int, int]]] = [{} for _ in lengths]
    active = [i for i, n in enumerate(lengths) if start[i] < n]
    while active:
        budget = max(_AXIS_EDGES, _ROUND_EDGES // len(active))
        asked: list[int] = []
        wanted: list[list[int]] = []
        for i in active:
            n = lengths[i]
            while start[i] < n:
                count, more = _seek(tried[i], min(n - start[i], MAX_COUNT), hint[i], budget)
                if more:
                    asked.append(i)
                    wanted.append(more)
                    break
                _, step, add = tried[i][count]
                chunks[i].append(Chunk(count, step, add))
                t[i] += count * step + add * (count * (count - 1) // 2)
                start[i] += count
                hint[i] = count
                tried[i] = {}
        active = asked
        if not asked:
            break
        ok, steps, adds = _try_counts(
            ideal,
            np.array(
                [
                    [firsts[i] + start[i] for i in asked],
                    [lengths[i] - start[i] for i in asked],
                    [t[i] for i in asked],
                ],
                dtype=np.int64,
            ),
            [len(w) for w in wanted],
            np.array(list(chain.from_iterable(wanted)), dtype=np.int64),
            tol_cycles,
        )
        results = list(zip(ok.tolist(), steps.tolist(), adds.tolist()))
        at = 0
        for i, w in zip(asked, wanted):
            tried[i].update(zip(w, results[at : at + len(w)]))
            at += len(w)
    return [AxisSchedule(lead, tuple(c)) for lead, c in zip(leads, chunks)]


def fit_axis(ideal: np.ndarray, tol_cycles: float) -> AxisSchedule:
    """The schedule of one axis in one segment from its ideal edges (cycles, increasing):
    as few chunks as a greedy search finds, each edge within ``tol_cycles`` of its ideal
    time (``tol_cycles`` at least 1: the device rounds to whole cycles)."""
    if len(ideal) == 0:
        return AxisSchedule(0, ())
    return _fit_axes(np.asarray(ideal, dtype=np.float64), [len(ideal)], tol_cycles)[0]


def plan_schedules(
    batch: SegmentBatch, cycles_per_tick: int, tol_cycles: float, table: np.ndarray | None = None
) -> dict[tuple[int, int], AxisSchedule]:
    """The schedules the wire must carry for ``batch``: ``(segment, axis)`` -> schedule for
    every moving axis whose prediction the device cannot make or that would stray past
    ``tol_cycles``; every other moving axis runs its prediction. Checked for the whole
    batch at once; the fit runs only for what is left."""
    if table is None:
        table = reciprocal_table(cycles_per_tick)
    n = batch.deltas
    codes = np.broadcast_to(batch.ramps[:, None], n.shape)
    ticks = np.broadcast_to(batch.ticks[:, None], n.shape)
    ok = predictable(n, ticks, codes)
    if ok.any():  # (a batch of ramps has nothing to check)
        ok[ok] = predicted_error(n[ok], ticks[ok], table, cycles_per_tick) <= tol_cycles
    where = list(zip(*(a.tolist() for a in np.nonzero((n != 0) & ~ok))))
    if not where:
        return {}
    i, k = np.array(where).T
    lengths = np.abs(n[i, k])
    ideal = ideal_edges_many(lengths, batch.ticks[i], batch.ramps[i], cycles_per_tick)
    return dict(zip(where, _fit_axes(ideal, lengths.tolist(), tol_cycles)))
