"""Planned moves -> joint-space segments for the device.

A segment is a straight line in joint space (3 sliders + extruder) run with one
normalised time profile whose speed is linear in time. Each move is cut at its
trapezoid's phase boundaries (accelerate, cruise, decelerate) and every phase into
equal pieces no longer than the move's chord step, so the effector stays within
the chord tolerance of the G-code line. Step targets are computed absolutely at
every segment end (``model.steps(model.ik(points))``, extruder ``round(e * spm)``)
and deltas are their differences, so rounding never drifts. Durations are
differences of rounded times since the move's start, ``round(t_end f) - round(t_start f)``
with ``t`` counted from the move's start: a move's segments depend on the move alone, not
on when the program reached it (so a program restarted part-way gives every move it
shares with the whole print the same segments, tick for tick); each move's duration is
rounded on its own (half a tick at most, not carried to the next).

``ramp`` is the start-speed fraction r = v_start / (v_start + v_end): over the
normalised time tau in [0, 1] the segment covers p(tau) = 2 r tau + (1 - 2r) tau^2
of its length (r = 1/2: constant speed; 0: starts at rest; 1: ends at rest).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cdprhost.effects.backlash import path_directions
from cdprhost.effects.base import MotionContext
from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.block_cuts import BlockLimits, block_cuts, equal_pieces
from cdprhost.motion.trapezoid import PlannedMoves
from firmware_protocol.ramp_profile import profile, ramp_codes_from_speeds
from firmware_protocol.segments import SegmentBatch, peak_step_rates

DEFAULT_CLOCK_HZ = 1_000_000
# the shortest segment planned: a 2.1 device announces the shortest it takes (CAPS; the
# AVR firmware 40 units of 10 us, its step tick), shorter ones are merged into the next.
# Every device gets at least this, so both devices are sent the same plan.
MIN_SEGMENT_S = 400e-6
#: passes of merging segments whose rounded steps exceed the device's step rate
RATE_MERGE_PASSES = 6
#: phases shorter than this (mm) are merged into a neighbour instead of making a segment
MIN_PHASE_MM = 1e-4


@dataclass(frozen=True)
class SegmentLimits:
    """What the device takes: its shortest segment (s) and its step rate on any one axis
    (steps/s; None: any). The planner keeps the speeds under the rate; these limits are
    for what rounding does to short segments (a 110 us piece can round to 2 steps)."""

    min_segment_s: float = MIN_SEGMENT_S
    max_step_rate: float | None = None
    #: a device that steps ramps from schedule blocks: ramps cut until their blocks fit
    blocks: BlockLimits | None = None
    #: the step rate the device's axes take summed (STEP_BUDGET; None: no such budget)
    total_step_rate: float | None = None


#: a device that announced nothing
DEFAULT_LIMITS = SegmentLimits()


@dataclass(frozen=True)
class PlannedSegments:
    """Consecutive segments as arrays; ``ramp`` is what firmware_protocol codes as code / 255."""

    steps_abs: np.ndarray  # (n, 4) int64: absolute steps after the segment (3 sliders, extruder)
    delta: np.ndarray  # (n, 4) int64: steps moved by the segment
    ticks: np.ndarray  # (n,) int64: duration in device clock ticks
    ramp: np.ndarray  # (n,) float64: start-speed fraction v0 / (v0 + v1), see module doc
    v_start: np.ndarray  # (n,) mm/s along the move's path
    v_end: np.ndarray  # (n,)
    line: np.ndarray  # (n,) int64 G-code line of the move
    layer: np.ndarray  # (n,) int32
    point: np.ndarray  # (n, 3) effector end point, machine frame
    e: np.ndarray  # (n,) filament position at the end (mm)
    t_end: np.ndarray  # (n,) s since the program started

    def __len__(self) -> int:
        return int(self.ticks.shape[0])

    def take(self, index: slice) -> PlannedSegments:
        """A contiguous run of segments (its ``delta`` stays valid: it is relative to the previous one)."""
        return PlannedSegments(*(getattr(self, f)[index] for f in self.__dataclass_fields__))


@dataclass(frozen=True)
class SegmentState:
    """Where the previous batch left the machine."""

    steps: np.ndarray  # (4,) int64
    point: np.ndarray  # (3,) machine frame
    directions: np.ndarray  # (3,) last direction of each module (backlash)

    @classmethod
    def at_home(cls, model: MachineModel, home_sliders: Any, e_steps: int = 0) -> SegmentState:
        home = np.asarray(home_sliders, dtype=float).reshape(3)
        steps = np.append(model.steps(home[None, :])[0], np.int64(e_steps))
        return cls(steps.astype(np.int64), model.home_point(home), np.ones(3))


@dataclass(frozen=True)
class Pieces:
    """Segment ends of a planned block: owner move, path position, speed, time since the move began."""

    owner: np.ndarray  # (m,) int64
    x: np.ndarray  # (m,) mm along the move
    v: np.ndarray  # (m,) mm/s at the end
    t: np.ndarray  # (m,) s since the move's start
    ends: np.ndarray  # (n,) int64: index of each move's last piece

    @property
    def last(self) -> np.ndarray:
        """(m,) bool: the piece ends its move."""
        flags = np.zeros(self.owner.shape[0], dtype=bool)
        flags[self.ends] = True
        return flags


def _phases(planned: PlannedMoves, min_phase: float) -> tuple[np.ndarray, ...]:
    """Phase lengths (accelerate, cruise, decelerate) with phases under ``min_phase`` merged away."""
    length = planned.length
    d_acc = planned.accel_distance
    d_dec = planned.decel_distance
    d_cru = length - d_acc - d_dec
    small_a, small_d = d_acc < min_phase, d_dec < min_phase
    d_cru = d_cru + np.where(small_a, d_acc, 0.0) + np.where(small_d, d_dec, 0.0)
    d_acc = np.where(small_a, 0.0, d_acc)
    d_dec = np.where(small_d, 0.0, d_dec)
    small_c = (d_cru < min_phase) & ((d_acc > 0) | (d_dec > 0))
    to_acc = small_c & (d_acc >= d_dec)
    d_acc = d_acc + np.where(to_acc, d_cru, 0.0)
    d_dec = d_dec + np.where(small_c & ~to_acc, d_cru, 0.0)
    d_cru = np.where(small_c, 0.0, d_cru)
    d_cru = np.where(
        (d_acc <= 0) & (d_dec <= 0), length, d_cru
    )  # no phase left: one cruise-like piece
    return d_acc, d_cru, d_dec


def piece_positions(planned: PlannedMoves, min_phase: float = MIN_PHASE_MM) -> Pieces:
    """Every segment end: phases cut into equal pieces no longer than the chord step (vectorised).

    At a piece end, ``dx`` into its phase (start speed v0, signed acceleration a):
    v = sqrt(v0^2 + 2 a dx) and, speed being linear in time, t = t0 + 2 dx / (v0 + v)
    (which is dx / v0 when cruising).
    """
    n = len(planned)
    d_acc, d_cru, d_dec = _phases(planned, min_phase)
    d = np.stack([d_acc, d_cru, d_dec], axis=1).reshape(-1)  # phase records, 3 per move
    count = np.where(
        d > 0, np.maximum(np.ceil(d / np.repeat(planned.chord_step, 3)), 1.0), 0.0
    ).astype(np.int64)
    # phase starts: position, speed, time, signed acceleration
    vs, vc, a = planned.v_start, planned.v_cruise, planned.accel
    v_top = np.minimum(
        np.sqrt(vs * vs + 2.0 * a * d_acc), vc
    )  # cruise speed (or where a merged phase left it)
    t_acc = 2.0 * d_acc / np.maximum(vs + v_top, 1e-300)
    t_dec0 = t_acc + d_cru / np.maximum(v_top, 1e-300)
    zero = np.zeros(n)
    x0 = np.stack([zero, d_acc, d_acc + d_cru], axis=1).reshape(-1)
    v0 = np.stack([vs, v_top, v_top], axis=1).reshape(-1)
    t0 = np.stack([zero, t_acc, t_dec0], axis=1).reshape(-1)
    acc2 = np.stack([2.0 * a, zero, -2.0 * a], axis=1).reshape(-1)
    owner_of = np.repeat(np.arange(n), 3)

    used = np.flatnonzero(count)  # phases that make pieces, in order
    cnt = count[used]
    phase = np.repeat(np.arange(used.shape[0]), cnt)  # compact phase record of every piece
    k = np.ones(phase.shape[0])  # 1, 2, ... within each phase
    starts = np.cumsum(cnt)[:-1]
    k[starts] = 1.0 - cnt[:-1]
    np.cumsum(k, out=k)
    dx = (d[used] / cnt).take(phase) * k
    pv0 = v0[used].take(phase)
    v = np.sqrt(np.maximum(pv0 * pv0 + acc2[used].take(phase) * dx, 0.0))
    t = t0[used].take(phase) + 2.0 * dx / np.maximum(pv0 + v, 1e-300)
    x = x0[used].take(phase) + dx
    owner = owner_of[used].take(phase)
    ends = np.cumsum(count.reshape(n, 3).sum(axis=1)) - 1
    x[ends] = planned.length
    v[ends] = planned.v_end
    return Pieces(owner, x, v, t, ends)


def _sliders(
    model: MachineModel, points: np.ndarray, state: SegmentState
) -> tuple[np.ndarray, np.ndarray]:
    """Commanded sliders along a path continuing from ``state`` (backlash directions carried)."""
    if "backlash" not in model.effects.names:
        return model.ik(points, path=True), state.directions
    plain = model.ik(
        np.vstack([state.point[None, :], points]),
        MotionContext(directions=np.zeros((points.shape[0] + 1, 3))),
    )
    dirs = path_directions(plain, initial=state.directions)[1:]
    return model.ik(points, MotionContext(directions=dirs)), dirs[-1]


def segment_moves(
    planned: PlannedMoves,
    model: MachineModel,
    state: SegmentState,
    *,
    e_steps_per_mm: float,
    clock_hz: float = DEFAULT_CLOCK_HZ,
    limits: SegmentLimits = DEFAULT_LIMITS,
) -> tuple[PlannedSegments, SegmentState]:
    """Cut planned moves into joint-space segments; returns the batch and the new state."""
    batch, state, _ = segment_moves_ends(
        planned, model, state, e_steps_per_mm=e_steps_per_mm, clock_hz=clock_hz, limits=limits
    )
    return batch, state


def segment_moves_ends(
    planned: PlannedMoves,
    model: MachineModel,
    state: SegmentState,
    *,
    e_steps_per_mm: float,
    clock_hz: float = DEFAULT_CLOCK_HZ,
    limits: SegmentLimits = DEFAULT_LIMITS,
) -> tuple[PlannedSegments, SegmentState, np.ndarray]:
    """:func:`segment_moves`, plus per planned move the number of segments up to its end."""
    pc = piece_positions(planned)
    owner, ends = pc.owner, pc.ends
    m = planned.moves
    n = owner.shape[0]
    frac = pc.x / planned.length.take(owner)
    rest = 1.0 - frac  # (1 - f) a + f b is exact at both ends of a move
    point = np.empty((n, 3))
    for k in range(3):  # column by column: 1-D gathers are several times faster than 2-D ones
        point[:, k] = m.start[:, k].take(owner) * rest + m.end[:, k].take(owner) * frac
    e = m.e_start.take(owner) * rest + m.e_end.take(owner) * frac
    # absolute times: a move's last piece ends exactly where the next move starts
    t_end = planned.t_start.take(owner) + pc.t
    t_end[ends] = np.append(planned.t_start[1:], planned.t_end)
    v = pc.v

    # segment starts: the previous piece of the same move, or the move's start
    t_begin = np.empty(n)
    v_begin = np.empty(n)
    if n:
        t_begin[1:] = t_end[:-1]
        v_begin[1:] = v[:-1]
        move_first = np.append(0, ends[:-1] + 1)
        t_begin[move_first] = planned.t_start
        v_begin[move_first] = planned.v_start
    # durations from the time since the move's start (see the module doc)
    local_end = pc.t.copy()
    local_end[ends] = planned.duration
    local_begin = np.empty(n)
    if n:
        local_begin[1:] = local_end[:-1]
        local_begin[move_first] = 0.0
    ticks = np.rint(local_end * clock_hz).astype(np.int64) - np.rint(local_begin * clock_hz).astype(
        np.int64
    )

    sliders, last_dirs = _sliders(model, point, state)
    steps = np.empty((n, 4), dtype=np.int64)
    steps[:, :3] = model.steps(sliders)
    steps[:, 3] = np.rint(e * e_steps_per_mm).astype(np.int64)
    delta = np.diff(steps, axis=0, prepend=state.steps[None, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        ramp = np.where(v_begin + v > 0, v_begin / (v_begin + v), 0.5)
    batch = PlannedSegments(
        steps,
        delta,
        ticks,
        ramp,
        v_begin,
        v,
        m.line.take(owner),
        m.layer.take(owner),
        point,
        e,
        t_end,
    )
    move_end = ends + 1
    min_ticks = max(1, math.ceil(limits.min_segment_s * clock_hz - 1e-9))
    if n and ticks.min() < min_ticks:
        batch, move_end = _at_least(batch, state.steps, move_end, min_ticks)
    if n and (limits.max_step_rate is not None or limits.total_step_rate is not None):
        batch, move_end = _within_step_rate(
            batch,
            state.steps,
            move_end,
            limits.max_step_rate or np.inf,
            clock_hz,
            limits.total_step_rate or np.inf,
        )
    if n and limits.blocks is not None:
        rate = limits.max_step_rate
        cuts = block_cuts(
            batch.ticks,
            batch.delta,
            batch.v_start,
            batch.v_end,
            limits.blocks,
            min_ticks,
            int(clock_hz),
            None if rate is None else rate * (1.0 - 1e-6),
        )
        if cuts:
            batch, move_end = _cut(batch, state, move_end, cuts, clock_hz, e_steps_per_mm)
    if n:
        state = replace(
            state,
            steps=steps[-1].copy(),
            point=point[-1].copy(),
            directions=np.asarray(last_dirs, float),
        )
    return batch, state, move_end


def _absorb(
    batch: PlannedSegments, prev_steps: np.ndarray, move_end: np.ndarray, keep: np.ndarray
) -> tuple[PlannedSegments, np.ndarray]:
    """Segments not kept merged into the next kept one (the last one is always kept).

    The kept one takes their time (the ticks are differences of rounded absolute
    times), their motion (through the absolute steps) and the start speed of the first
    of them. ``move_end`` (segments up to each move's end) is counted again. A device
    takes no segment under its shortest (PROTOCOL.md, CAPS); the merged one is also
    slower than the rounded sliver it absorbed.
    """
    keep = keep.copy()
    keep[-1] = True
    ticks = np.diff(np.cumsum(batch.ticks)[keep], prepend=0)
    steps = batch.steps_abs[keep]
    delta = np.diff(steps, axis=0, prepend=prev_steps[None, :])
    kept = np.flatnonzero(keep)
    first = np.concatenate([[0], kept[:-1] + 1])  # the first segment each kept one absorbs
    v_start = batch.v_start[first]
    v_end = batch.v_end[keep]
    with np.errstate(invalid="ignore", divide="ignore"):
        ramp = np.where(v_start + v_end > 0, v_start / (v_start + v_end), 0.5)
    merged = PlannedSegments(
        steps,
        delta,
        ticks,
        ramp,
        v_start,
        v_end,
        batch.line[keep],
        batch.layer[keep],
        batch.point[keep],
        batch.e[keep],
        batch.t_end[keep],
    )
    counted = np.cumsum(keep)
    return merged, np.where(move_end > 0, counted[np.maximum(move_end, 1) - 1], 0)


def _at_least(
    batch: PlannedSegments, prev_steps: np.ndarray, move_end: np.ndarray, min_ticks: int
) -> tuple[PlannedSegments, np.ndarray]:
    """Segments under ``min_ticks`` merged into the next (a short last one takes the one
    before it); a single one still short is stretched to ``min_ticks``."""
    keep = batch.ticks >= min_ticks
    if not keep[-1] and len(batch) > 1:
        keep[-2] = False
    batch, move_end = _absorb(batch, prev_steps, move_end, keep)
    if batch.ticks[-1] < min_ticks:
        ticks = batch.ticks.copy()
        ticks[-1] = min_ticks
        batch = replace(batch, ticks=ticks)
    return batch, move_end


def _cut(
    batch: PlannedSegments,
    state: SegmentState,
    move_end: np.ndarray,
    cuts: dict[int, int],
    clock_hz: float,
    e_steps_per_mm: float,
) -> tuple[PlannedSegments, np.ndarray]:
    """Segments ``cuts`` names split into that many equal-time pieces (block_cuts): the
    pieces keep the segment's line in joint space, its steps and its time; their points are
    where the segment's profile is at each cut, their filament positions those of the
    extruder steps issued by then (a restart from a piece sets the extruder to that E's
    rounding: it must be the steps the device stood at)."""
    codes = ramp_codes_from_speeds(batch.v_start, batch.v_end)
    parts: list[PlannedSegments] = []
    start = 0
    for i in sorted(cuts):
        if i > start:
            parts.append(batch.take(slice(start, i)))
        prev_steps = batch.steps_abs[i - 1] if i else state.steps
        prev_point = batch.point[i - 1] if i else state.point
        tau, ticks, steps, speeds = equal_pieces(
            int(batch.ticks[i]),
            batch.delta[i],
            float(batch.v_start[i]),
            float(batch.v_end[i]),
            int(codes[i]),
            cuts[i],
        )
        p = profile(tau, int(codes[i]))[:, None]
        k = tau.shape[0]
        steps_abs = prev_steps[None, :] + np.cumsum(steps, axis=0)
        e = batch.e[i] - (batch.steps_abs[i, 3] - steps_abs[:, 3]) / e_steps_per_mm
        with np.errstate(invalid="ignore", divide="ignore"):
            ramp = np.where(
                speeds[:-1] + speeds[1:] > 0, speeds[:-1] / (speeds[:-1] + speeds[1:]), 0.5
            )
        parts.append(
            PlannedSegments(
                steps_abs,
                steps,
                ticks,
                ramp,
                speeds[:-1],
                speeds[1:],
                np.repeat(batch.line[i], k),
                np.repeat(batch.layer[i], k),
                prev_point[None, :] + (batch.point[i] - prev_point)[None, :] * p,
                e,
                batch.t_end[i] - (1.0 - tau) * batch.ticks[i] / clock_hz,
            )
        )
        start = i + 1
    if start < len(batch):
        parts.append(batch.take(slice(start, len(batch))))
    merged = PlannedSegments(
        *(
            np.concatenate([getattr(b, f) for b in parts])
            for f in PlannedSegments.__dataclass_fields__
        )
    )
    pieces = np.ones(len(batch), np.int64)
    pieces[list(cuts)] = list(cuts.values())
    counted = np.cumsum(pieces)
    return merged, np.where(move_end > 0, counted[np.maximum(move_end, 1) - 1], 0)


def peak_rates(batch: PlannedSegments, clock_hz: float) -> np.ndarray:
    """(n,) the fastest axis's peak step rate of each segment, as the device checks it
    (PROTOCOL.md 5.1, from the ramp codes the wire carries)."""
    return np.asarray(axis_peak_rates(batch, clock_hz).max(axis=1))


def axis_peak_rates(batch: PlannedSegments, clock_hz: float) -> np.ndarray:
    """(n, 4) each axis's peak step rate of each segment, as the device checks it."""
    codes = ramp_codes_from_speeds(batch.v_start, batch.v_end)
    wire = SegmentBatch(batch.ticks, batch.delta, codes)
    return np.asarray(peak_step_rates(wire, int(clock_hz)))


def _within_step_rate(
    batch: PlannedSegments,
    prev_steps: np.ndarray,
    move_end: np.ndarray,
    max_step_rate: float,
    clock_hz: float,
    total_step_rate: float = np.inf,
) -> tuple[PlannedSegments, np.ndarray]:
    """Segments whose rounded steps exceed ``max_step_rate`` on an axis, or
    ``total_step_rate`` summed over the axes, merged into the next (the
    last one into the one before), a few passes: the speeds were planned under the
    rate, so what exceeds it is the rounding of a short piece, which its neighbour
    averages out. What is still over after the passes is left to the feed's check
    (StepRateError names it)."""
    limit = max_step_rate * (1.0 - 1e-6)  # the device's integer test, with float slack
    total = total_step_rate * (1.0 - 1e-6)
    for _ in range(RATE_MERGE_PASSES):
        rates = axis_peak_rates(batch, clock_hz)
        over = (rates.max(axis=1) > limit) | (rates.sum(axis=1) > total)
        if not over.any() or len(batch) < 2:
            break
        keep = ~over
        if over[-1]:
            keep[-2] = False  # the last merges backwards: the one before absorbs into it
        batch, move_end = _absorb(batch, prev_steps, move_end, keep)
    return batch, move_end


class Segmenter:
    """Stateful wrapper: feeds planned blocks through :func:`segment_moves` in order."""

    def __init__(
        self,
        model: MachineModel,
        home_sliders: Any,
        *,
        e_steps_per_mm: float,
        clock_hz: float = DEFAULT_CLOCK_HZ,
        limits: SegmentLimits = DEFAULT_LIMITS,
    ):
        self.model = model
        self.limits = limits
        self.home_sliders = np.asarray(home_sliders, dtype=float)
        self.e_steps_per_mm = float(e_steps_per_mm)
        self.clock_hz = float(clock_hz)
        self.state = SegmentState.at_home(model, self.home_sliders)
        self.segments = 0

    def __call__(self, planned: PlannedMoves) -> PlannedSegments:
        return self.segment_block(planned)[0]

    def segment_block(self, planned: PlannedMoves) -> tuple[PlannedSegments, np.ndarray]:
        """The batch and, per planned move, the number of segments up to its end."""
        batch, self.state, move_end = segment_moves_ends(
            planned,
            self.model,
            self.state,
            e_steps_per_mm=self.e_steps_per_mm,
            clock_hz=self.clock_hz,
            limits=self.limits,
        )
        self.segments += len(batch)
        return batch, move_end

    def home(self) -> None:
        """After G28: sliders at their endstops, the extruder where it was."""
        self.state = SegmentState.at_home(self.model, self.home_sliders, int(self.state.steps[3]))

    def extruder_at(self, e_mm: float) -> None:
        """The extruder stands at program E ``e_mm``: its step count becomes that E's
        rounding (no motion), so the next segments' deltas are those of the whole print."""
        steps = self.state.steps.copy()
        steps[3] = np.int64(np.rint(e_mm * self.e_steps_per_mm))
        self.state = replace(self.state, steps=steps)
