"""One straight move from where the device is to a target, as wire segments.

Used by the jog screen and the calibration wizard's shell: the move goes
through the same planner (limits, ramps, ends at rest) and segmenter (chord
tolerance, absolute steps) as a print, starting from the device's step position.
"""

from __future__ import annotations

import numpy as np

from cdprhost.kinematics import MachineModel
from cdprhost.motion import MoveBlock, PlannedMoves, ProgramPlanner, Segmenter
from cdprhost.motion.segments import SegmentState
from cdprhost.profile import MachineProfile
from firmware_protocol.segments import SegmentBatch as WireBatch
from firmware_protocol.segments import ramp_codes_from_speeds


def straight_move(profile: MachineProfile, model: MachineModel, steps: tuple[int, int, int, int],
                  target: tuple[float, float, float], *, feedrate_mm_s: float, clock_hz: int) -> tuple[WireBatch, float]:
    """Segments that take the effector from absolute ``steps`` to ``target`` (machine frame).

    Returns the wire batch and its duration in seconds. The start point is the
    forward kinematics of the current slider positions.
    """
    steps_arr = np.asarray(steps, dtype=np.int64).reshape(4)
    start = model.fk(model.sliders_from_steps(steps_arr[:3])[None, :])[0]
    block = MoveBlock.from_arrays(start, np.asarray(target, dtype=float), feedrate=feedrate_mm_s)
    planner = ProgramPlanner(profile, model)
    planner.position = start.copy()
    planned = [p for p in (*planner.moves(block)[1], *planner.finish()) if isinstance(p, PlannedMoves)]
    segmenter = Segmenter(model, profile.drive.home_mm, e_steps_per_mm=profile.extruder.steps_per_mm, clock_hz=clock_hz)
    segmenter.state = SegmentState(steps_arr, start, np.ones(3))
    batches = [segmenter(p) for p in planned]
    batches = [b for b in batches if len(b)]
    if not batches:
        return WireBatch(np.zeros(0, np.int64), np.zeros((0, 4), np.int64)), 0.0
    ticks = np.concatenate([b.ticks for b in batches])
    deltas = np.concatenate([b.delta for b in batches])
    v0 = np.concatenate([b.v_start for b in batches])
    v1 = np.concatenate([b.v_end for b in batches])
    ramps = ramp_codes_from_speeds(v0, v1)
    return WireBatch(ticks, deltas, ramps), float(ticks.sum()) / clock_hz
