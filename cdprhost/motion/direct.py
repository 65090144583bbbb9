"""Direct moves outside a G-code program (jog, calibration poses) and the wire hand-off.

``direct_path`` plans straight moves through waypoints from a known machine state
with the same planner (limits, ramps, ends at rest) and segmenter (chord tolerance,
absolute steps) as a print. ``to_wire`` turns planned segments into the protocol's
segment batch; the print job, the jog screen and the calibration wizard all use it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from cdprhost.kinematics.machine import MachineModel
from cdprhost.motion.limits import Caps
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.planner import Planner
from cdprhost.motion.segments import (
    DEFAULT_LIMITS,
    PlannedSegments,
    Segmenter,
    SegmentLimits,
    SegmentState,
)
from cdprhost.profile.models import MachineProfile
from firmware_protocol.ramp_profile import ramp_codes_from_speeds
from firmware_protocol.segments import SegmentBatch


def to_wire(batch: PlannedSegments) -> SegmentBatch:
    """Planned segments -> the protocol's batch (durations, step deltas, ramp codes)."""
    return SegmentBatch(
        batch.ticks, batch.delta, ramp_codes_from_speeds(batch.v_start, batch.v_end)
    )


def state_at_steps(model: MachineModel, steps: ArrayLike) -> SegmentState:
    """Machine state from the device's absolute steps (position by forward kinematics)."""
    arr = np.asarray(steps, dtype=np.int64).reshape(4)
    point = model.fk(model.sliders_from_steps(arr[:3])[None, :])[0]
    return SegmentState(arr, point, np.ones(3))


def direct_path(
    profile: MachineProfile,
    model: MachineModel,
    state: SegmentState,
    points: ArrayLike,
    *,
    feedrate_mm_s: float,
    clock_hz: int,
    limits: SegmentLimits = DEFAULT_LIMITS,
) -> tuple[SegmentBatch, float, SegmentState]:
    """Segments through ``points`` (machine frame, in order) starting from ``state``, for
    a device that takes ``limits`` (``profile`` already capped to its step rate, as a
    print's: :func:`~cdprhost.motion.device_limits.caps_for_device`).

    Returns the wire batch, its duration in seconds, and the state after it.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    start = np.vstack([state.point[None, :], pts[:-1]])
    caps = Caps.for_profile(profile)
    planner = Planner(caps, model.geometry.outlets)
    segmenter = Segmenter(
        model,
        profile.drive.home_mm,
        e_steps_per_mm=profile.extruder.steps_per_mm,
        clock_hz=clock_hz,
        limits=limits,
    )
    segmenter.state = state
    planned = (
        planner.push(MoveBlock.from_arrays(start, pts, feedrate=feedrate_mm_s)) + planner.flush()
    )
    batches = [b for b in (segmenter(p) for p in planned) if len(b)]
    if not batches:
        return SegmentBatch(np.zeros(0, np.int64), np.zeros((0, 4), np.int64)), 0.0, state
    wires = [to_wire(b) for b in batches]
    wire = SegmentBatch.concat(wires) if len(wires) > 1 else wires[0]
    return wire, float(wire.ticks.sum()) / clock_hz, segmenter.state
