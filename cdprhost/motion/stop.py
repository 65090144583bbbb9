"""Stopping a print within the motion already sent, and starting it again (pure).

The device executes what it was sent; the host cannot take segments back. To stop, the
host stops feeding the plan and sends instead the planned path *after* the last sent
segment, retimed: the speed falls from the last sent segment's end speed ``v0`` at the
deceleration limit, ``v(x) = min(v_plan(x), sqrt(v0^2 - 2 a x))``, until it reaches
zero (the segment where it does is cut there). Speeds never exceed the plan's, so every
junction, speed and step-rate limit the plan respected still holds; the extruder does not
move (no extrusion while stopping), and a retract follows at rest.

Starting again from rest at the same place is the mirror image:
``v(x) = min(v_plan(x), sqrt(2 a x))`` until the retimed speed meets the plan, from where
the plan continues unchanged (same segments, same deltas).

Both work on :class:`PlannedSegments` (the plan's own segments: points, speeds, steps),
so the path is exactly the planned one. ``accel`` is the tightest acceleration the
profile allows along that path (:func:`path_accel`: Cartesian and module limits).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.motion.limits import Caps, move_caps
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.segments import PlannedSegments
from cdprhost.profile.models import MachineProfile

#: segments shorter than this (mm of effector path) carry no Cartesian motion (extruder only)
NO_PATH_MM = 1e-6
#: a retimed speed within this share of the plan's has met it
MERGE_TOL = 1e-6


@dataclass(frozen=True)
class Retimed:
    """Segments ``0..count-1`` of a path retimed; the last one possibly cut short."""

    segments: PlannedSegments
    count: int  # planned segments used (the last one cut when ``cut < 1``)
    cut: float = 1.0  # share of the last one's path that is run
    merged: bool = True  # the retimed speed reached its goal (rest, or the plan) in the path


def path_lengths(start_point: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n,) Cartesian length of each segment from ``start_point`` through ``points``."""
    prev = np.vstack([np.asarray(start_point, dtype=float).reshape(1, 3), points[:-1]])
    return np.asarray(np.linalg.norm(points - prev, axis=1))


def path_accel(
    profile: MachineProfile, outlets: np.ndarray, start: np.ndarray, pts: np.ndarray
) -> float:
    """The tightest acceleration (mm/s^2) the profile's limits allow along the path
    ``start -> pts`` (Cartesian, statics and module limits, as the planner computes them)."""
    caps = Caps.for_profile(profile)
    starts = np.vstack([np.asarray(start, dtype=float).reshape(1, 3), pts[:-1]])
    moving = np.linalg.norm(pts - starts, axis=1) > NO_PATH_MM
    if not moving.any():
        return float(caps.max_accel)
    block = MoveBlock.from_arrays(starts[moving], pts[moving], feedrate=caps.max_velocity)
    mc = move_caps(block, outlets, caps, chord=False)
    return float(max(np.min(mc.accel), 1.0))


def _times_to_ticks(seconds: np.ndarray, clock_hz: float) -> np.ndarray:
    """Durations -> ticks by rounding cumulative times (no drift), each at least 1."""
    ends = np.rint(np.cumsum(seconds) * clock_hz).astype(np.int64)
    ticks = np.diff(ends, prepend=0)
    return np.maximum(ticks, 1)


def _retimed(
    path: PlannedSegments,
    n: int,
    lengths: np.ndarray,
    v_start: np.ndarray,
    v_end: np.ndarray,
    clock_hz: float,
    t0: float,
    flat: np.ndarray,
) -> PlannedSegments:
    """Segments ``0..n-1`` of ``path`` with new speeds (durations and ramps follow);
    ``flat``: extruder-only segments (they keep their planned durations)."""
    seg = path.take(slice(0, n))
    with np.errstate(invalid="ignore", divide="ignore"):
        sec = np.where(
            ~flat[:n],
            2.0 * lengths / np.maximum(v_start + v_end, 1e-12),
            seg.ticks / clock_hz,  # extruder-only: as planned
        )
        ramp = np.where(v_start + v_end > 0, v_start / (v_start + v_end), 0.5)
    ticks = _times_to_ticks(sec, clock_hz)
    return PlannedSegments(
        seg.steps_abs,
        seg.delta,
        ticks,
        ramp,
        v_start,
        v_end,
        seg.line,
        seg.layer,
        seg.point,
        seg.e,
        t0 + np.cumsum(ticks) / clock_hz,
    )


def decelerate(
    path: PlannedSegments,
    start_steps: np.ndarray,
    start_point: np.ndarray,
    v0: float,
    accel: float,
    clock_hz: float,
    t0: float = 0.0,
) -> Retimed:
    """The plan's path after the last sent segment (which ended at ``start_steps``,
    ``start_point``, speed ``v0``), retimed to come to rest at ``accel``, without extrusion.

    ``merged`` is False when ``path`` ends before the machine is at rest: give more of it.
    """
    if v0 <= 1e-9 or len(path) == 0:
        return Retimed(path.take(slice(0, 0)), 0, 1.0, merged=v0 <= 1e-9)
    lengths = path_lengths(start_point, path.point)
    flat = lengths <= NO_PATH_MM
    plan = path.v_end.copy()
    # an extruder-only segment is no path to stop along: the stop ends before it
    plan[flat] = 0.0
    plan[:-1][flat[1:]] = 0.0
    x = np.cumsum(lengths)
    cap = np.sqrt(np.maximum(v0 * v0 - 2.0 * accel * x, 0.0))
    v_end = np.minimum(plan, cap)
    rest = np.flatnonzero(v_end <= 1e-9)
    if rest.size == 0:
        return Retimed(path.take(slice(0, 0)), 0, 1.0, merged=False)
    k = int(rest[0])
    if flat[k]:  # stopped at the end of the segment before
        if k == 0:
            return Retimed(path.take(slice(0, 0)), 0, 1.0)
        k -= 1
    n = k + 1
    v_end = v_end[:n].copy()
    v_end[-1] = 0.0
    v_start = np.append(v0, v_end[:-1])
    lens = lengths[:n].copy()
    # where the last one brings the speed to zero at ``accel``: cut it there
    stop_len = v_start[-1] ** 2 / (2.0 * accel)
    cut = 1.0
    if lens[-1] > NO_PATH_MM and stop_len < lens[-1]:
        cut = max(stop_len / lens[-1], 1e-9)
        lens[-1] = stop_len
    seg = _retimed(path, n, lens, v_start, v_end, clock_hz, t0, flat)
    prev_steps = seg.steps_abs[-2] if n > 1 else np.asarray(start_steps, dtype=np.int64)
    prev_point = seg.point[-2] if n > 1 else np.asarray(start_point, dtype=float)
    steps = seg.steps_abs.copy()
    point = seg.point.copy()
    if cut < 1.0:
        steps[-1, :3] = prev_steps[:3] + np.rint(cut * seg.delta[-1, :3]).astype(np.int64)
        point[-1] = prev_point + cut * (seg.point[-1] - prev_point)
    steps[:, 3] = int(start_steps[3])  # no extrusion while stopping
    delta = np.diff(steps, axis=0, prepend=np.asarray(start_steps, np.int64).reshape(1, 4))
    ticks = seg.ticks
    if cut < 1.0 and v_start[-1] > 0:
        # rounding the cut to whole steps must not start it faster than the plan ran there:
        # joint speed 2 n / D at its start (it ends at rest) <= |delta| v / L of the plan
        full = np.abs(path.delta[k, :3]).astype(float)
        n_cut = np.abs(delta[-1, :3]).astype(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            need = np.where(full > 0, 2.0 * n_cut * lengths[k] / (full * v_start[-1]), 0.0)
        ticks = ticks.copy()
        ticks[-1] = max(int(ticks[-1]), int(np.ceil(float(need.max()) * clock_hz)))
    e = np.full(n, np.nan)  # the filament is not where the program has it
    out = PlannedSegments(
        steps,
        delta,
        ticks,
        seg.ramp,
        seg.v_start,
        seg.v_end,
        seg.line,
        seg.layer,
        point,
        e,
        seg.t_end,
    )
    return Retimed(out, n, cut)


def accelerate(
    path: PlannedSegments, start_point: np.ndarray, accel: float, clock_hz: float, t0: float = 0.0
) -> Retimed:
    """The plan's path from ``start_point`` retimed to start from rest at ``accel`` until
    it meets the plan; ``count`` segments are retimed (the rest of ``path`` goes as planned).
    ``merged`` is False when ``path`` ends before the speed meets the plan."""
    lengths = path_lengths(start_point, path.point)
    x = np.cumsum(lengths)
    cap = np.sqrt(2.0 * accel * x)
    flat = lengths <= NO_PATH_MM
    met = (path.v_end <= cap * (1.0 + MERGE_TOL)) | flat
    if len(path) == 0 or not met.any():
        return Retimed(path.take(slice(0, 0)), 0, merged=False)
    n = int(np.flatnonzero(met)[0]) + 1
    v_end = np.minimum(path.v_end[:n], cap[:n])
    v_end[-1] = path.v_end[n - 1]  # met: continue exactly as planned
    v_start = np.append(0.0, v_end[:-1])
    seg = _retimed(path, n, lengths[:n], v_start, v_end, clock_hz, t0, flat)
    return Retimed(seg, n)


def extruder_move(
    steps: np.ndarray,
    e_steps: int,
    speed_mm_s: float,
    accel_mm_s2: float,
    steps_per_mm: float,
    clock_hz: float,
) -> PlannedSegments:
    """Extruder-only motion at rest from ``steps`` (a retract when ``e_steps`` < 0): two
    segments, up to ``speed_mm_s`` and back to rest (within ``accel_mm_s2``)."""
    if e_steps == 0:
        return _empty(steps)
    first = e_steps // 2 if e_steps > 0 else -((-e_steps) // 2)
    parts = np.array([first, e_steps - first], dtype=np.int64)
    # each half from (to) rest: its peak speed 2 part / t and acceleration 2 part / t^2
    half = float(np.abs(parts).max()) / steps_per_mm
    half_t = max(
        2.0 * half / max(speed_mm_s, 1e-9), float(np.sqrt(2.0 * half / max(accel_mm_s2, 1e-9)))
    )
    ticks = np.maximum(np.full(2, int(np.ceil(half_t * clock_hz))), 1)
    base = np.asarray(steps, dtype=np.int64).reshape(4)
    delta = np.zeros((2, 4), dtype=np.int64)
    delta[:, 3] = parts
    abs_steps = base + np.cumsum(delta, axis=0)
    v_peak = 2.0 * half / half_t
    n = 2
    return PlannedSegments(
        abs_steps,
        delta,
        ticks,
        np.array([0.0, 1.0]),
        np.array([0.0, v_peak]),
        np.array([v_peak, 0.0]),
        np.zeros(n, np.int64),
        np.zeros(n, np.int32),
        np.full((n, 3), np.nan),
        np.full(n, np.nan),
        np.cumsum(ticks) / clock_hz,
    )


def _empty(steps: np.ndarray) -> PlannedSegments:
    z = np.zeros(0)
    return PlannedSegments(
        np.zeros((0, 4), np.int64),
        np.zeros((0, 4), np.int64),
        np.zeros(0, np.int64),
        z,
        z,
        z,
        np.zeros(0, np.int64),
        np.zeros(0, np.int32),
        np.zeros((0, 3)),
        z,
        z,
    )


def concat_segments(parts: list[PlannedSegments]) -> PlannedSegments:
    """Consecutive batches as one (deltas stay valid: each is relative to the one before)."""
    if len(parts) == 1:
        return parts[0]
    fields = PlannedSegments.__dataclass_fields__
    return PlannedSegments(*(np.concatenate([getattr(p, f) for p in parts]) for f in fields))
