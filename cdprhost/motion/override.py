"""Speed and flow overrides (M220 / M221 while printing) applied to segments already planned.

The job plans far ahead (a planned block is often tens of seconds of motion), so an
operator's override cannot wait for the planner: the streamer applies it to the segments
it has not sent yet, one feed at a time, with these pure functions.

Speed (:func:`retime`): the segments keep their geometry and steps; their speeds are
replanned along the same path. Each segment end may go as fast as ``factor`` times its
planned speed, but never faster than the limits of the path there (the profile's
Cartesian, extruder and module speed limits, the junction deviation at the corners
between segments, the device's step rate and shortest segment); the speed at the first
end is the one the device is already moving at, at the last end at most the planned one
(the next batch starts from there); and the speed changes at most at the acceleration
the limits allow along each segment (at least what the plan itself used there). That is
the largest speed profile under those bounds: a forward and a backward pass, each a
cumulative minimum (vectorised). Planned stops stay stops (``factor`` times zero).

Flow (:func:`scale_flow`): the extruder's absolute steps after a point grow by
``factor`` times what the plan feeds from there (retractions too), so the axis stays
continuous; the filament positions (``e``) stay the program's, so a resume point taken
while an override is in effect names the same place in the file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.motion.junction import junction_v2
from cdprhost.motion.limits import Caps, move_caps
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.segments import DEFAULT_LIMITS, PlannedSegments, SegmentLimits

MIN_PERCENT = 10
MAX_PERCENT = 500
_NO_PATH_MM = 1e-6


def check_percent(what: str, percent: float) -> float:
    """``percent`` as a factor; a clear refusal outside 10-500 %."""
    value = float(percent)
    if not np.isfinite(value) or not MIN_PERCENT <= value <= MAX_PERCENT:
        raise ValueError(
            f"{what} override S{percent:g}: out of range (S{MIN_PERCENT}-S{MAX_PERCENT}, percent)"
        )
    return value / 100.0


@dataclass(frozen=True)
class FlowEpoch:
    """Where the current flow factor took over: the planned and the sent extruder steps there."""

    planned_steps: int = 0
    sent_steps: int = 0
    factor: float = 1.0

    @property
    def identity(self) -> bool:
        return self.factor == 1.0 and self.planned_steps == self.sent_steps

    def steps(self, planned: np.ndarray) -> np.ndarray:
        """The extruder steps to send for ``planned`` absolute steps."""
        if self.identity:
            return planned
        scaled = self.sent_steps + (planned - self.planned_steps) * self.factor
        return np.rint(scaled).astype(np.int64)

    def changed(self, factor: float, planned_last: int, sent_last: int) -> FlowEpoch:
        """A new factor from the last segment sent on (its planned and sent steps)."""
        return FlowEpoch(int(planned_last), int(sent_last), float(factor))


def scale_flow(batch: PlannedSegments, epoch: FlowEpoch, prev_steps: np.ndarray) -> PlannedSegments:
    """``batch`` with its extruder steps under ``epoch`` (``prev_steps``: the absolute steps
    sent just before it, for the first delta)."""
    if epoch.identity or not len(batch):
        return batch
    e = epoch.steps(batch.steps_abs[:, 3])
    steps = batch.steps_abs.copy()
    steps[:, 3] = e
    delta = np.diff(steps, axis=0, prepend=np.asarray(prev_steps, dtype=np.int64)[None, :])
    return PlannedSegments(
        steps,
        delta,
        batch.ticks,
        batch.ramp,
        batch.v_start,
        batch.v_end,
        batch.line,
        batch.layer,
        batch.point,
        batch.e,
        batch.t_end,
    )


@dataclass(frozen=True)
class Retimed:
    batch: PlannedSegments
    planned_s: float  # the segments' planned duration
    new_s: float  # ... at the override

    @property
    def ratio(self) -> float:
        return self.new_s / self.planned_s if self.planned_s > 0 else 1.0


def retime(
    batch: PlannedSegments,
    factor: float,
    *,
    start_point: np.ndarray,
    v0: float,
    caps: Caps,
    outlets: np.ndarray,
    clock_hz: float,
    limits: SegmentLimits = DEFAULT_LIMITS,
    flow: float = 1.0,
    e_steps_per_mm: float | None = None,
) -> Retimed:
    """``batch`` (as planned, at 100 %) at ``factor`` times its speeds, starting at ``v0``
    mm/s from ``start_point`` (the end of the last segment sent); see the module doc.

    ``flow``: the flow factor already in the batch's extruder steps (:func:`scale_flow`);
    with ``e_steps_per_mm`` the extruder's limits bound the speeds of what it feeds, and
    extruder-only segments (retractions) take ``flow`` times their planned time."""
    n = len(batch)
    planned_s = float(batch.ticks.sum()) / clock_hz
    if n == 0:
        return Retimed(batch, 0.0, 0.0)
    vp = np.append(batch.v_start[:1], batch.v_end)  # planned speed at the n + 1 ends
    dt = batch.ticks / clock_hz
    starts = np.vstack([np.asarray(start_point, dtype=float).reshape(1, 3), batch.point[:-1]])
    length = np.linalg.norm(batch.point - starts, axis=1)  # a segment is a straight piece
    # extruder-only segments (retractions) keep their plan; the effector meets them at rest
    moving = length > _NO_PATH_MM
    fed = (
        np.zeros(n)
        if e_steps_per_mm is None
        else np.asarray(batch.delta[:, 3], dtype=float) / float(e_steps_per_mm)
    )
    block = MoveBlock.from_arrays(
        starts, batch.point, e_start=np.zeros(n), e_end=fed, feedrate=caps.max_velocity
    )
    mc = move_caps(block, outlets, caps, chord=False)
    seg_v2 = np.where(moving, mc.v2_cap, 0.0)
    # the device: its step rate on any axis, the budget its axes share and its shortest
    # segment bound the average speed
    worst = np.abs(batch.delta).max(axis=1).astype(float)
    summed = np.abs(batch.delta).sum(axis=1).astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        if limits.max_step_rate is not None:
            seg_v2 = np.minimum(
                seg_v2, np.where(worst > 0, (limits.max_step_rate * length / worst) ** 2, np.inf)
            )
        if limits.total_step_rate is not None:
            seg_v2 = np.minimum(
                seg_v2,
                np.where(summed > 0, (limits.total_step_rate * length / summed) ** 2, np.inf),
            )
        seg_v2 = np.minimum(seg_v2, (length / limits.min_segment_s) ** 2)
        plan_a = np.where(moving, np.abs(np.diff(vp**2)) / (2.0 * np.maximum(length, 1e-12)), 0.0)
    # an end is bounded by both segments it joins and by the corner between them
    cap = np.minimum(np.append(seg_v2, np.inf), np.append(np.inf, seg_v2))
    if n > 1:
        jd = caps.junction_deviation
        corner = junction_v2(mc.unit, mc.kinematic, mc.accel, mc.length, jd)
        cap[1:-1] = np.minimum(cap[1:-1], corner)
    # accelerations: the limits', and never below what the plan used (its own file limits)
    accel = np.maximum(np.minimum(mc.accel, max(float(plan_a.max()), 1.0)), plan_a)
    accel = np.where(moving, accel, 0.0)
    reach = np.append(0.0, np.cumsum(2.0 * accel * length))  # (v^2 change allowed), cumulative
    vp2 = vp * vp
    wanted = np.minimum(vp2 * factor * factor, cap)
    braking = np.minimum(v0 * v0 - reach, cap)  # slowing from v0 is always allowed
    # the plan's own speeds stay allowed (they met every limit), the extruder's share of them
    # divided by the flow (it feeds more per mm)
    upper = np.maximum.reduce([vp2 / max(flow, 1.0) ** 2, wanted, braking])
    u = np.minimum(upper, np.maximum(wanted, braking))
    u[0] = v0 * v0
    u[-1] = min(u[-1], vp2[-1])
    # largest profile under u with |d(v^2)| <= 2 a ds: forward, then backward cumulative minima
    fwd = np.minimum.accumulate(u - reach) + reach
    back = (np.minimum.accumulate((fwd + reach)[::-1]))[::-1] - reach
    v2 = np.minimum(fwd, back)
    v2[0] = v0 * v0  # (the backward pass never asks less: v0 was feasible)
    v = np.sqrt(np.maximum(v2, 0.0))
    va = np.where(moving, v[:-1], batch.v_start)
    vb = np.where(moving, v[1:], batch.v_end)
    with np.errstate(divide="ignore", invalid="ignore"):
        sec = np.where(moving & (va + vb > 1e-9), 2.0 * length / (va + vb), dt * max(flow, 1.0))
        ramp = np.where(moving, np.where(va + vb > 0, va / (va + vb), 0.5), batch.ramp)
    ends = np.rint(np.cumsum(sec) * clock_hz).astype(np.int64)
    ticks = np.maximum(np.diff(ends, prepend=0), 1)
    out = PlannedSegments(
        batch.steps_abs,
        batch.delta,
        ticks,
        ramp,
        va.copy(),
        vb.copy(),
        batch.line,
        batch.layer,
        batch.point,
        batch.e,
        batch.t_end,  # program time as planned: progress and the resume point stay the plan's
    )
    return Retimed(out, planned_s, float(ticks.sum()) / clock_hz)
