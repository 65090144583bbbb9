"""The exact place a killed job's device stopped, from the device itself.

A resume point is saved every few seconds; a host that is killed between saves leaves
one a little behind. The device knows better: if it still holds the fault its watchdog
raised for that job (same boot, not cleared since), its ``segments_done`` is the exact
last executed segment. Planning is deterministic, so re-planning the dead job's program
and counting from its first segment names that segment's G-code line, point and
filament position.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import Any

import numpy as np

from cdprhost.job.resume import ResumePoint
from cdprhost.job.resume_items import INSERTED_LINE, PlanSpec, Restart
from cdprhost.kinematics.machine import MachineModel
from cdprhost.link import DeviceStatus
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.segments import DEFAULT_LIMITS, PlannedSegments, SegmentLimits
from cdprhost.profile.models import MachineProfile


def refine_point(
    point: ResumePoint,
    found: DeviceStatus,
    boot_id: int,
    items: Callable[[PlanSpec], Iterable[Any]],
    profile: MachineProfile,
    model: MachineModel,
    *,
    clock_hz: int,
    batch_moves: int,
    limits: SegmentLimits = DEFAULT_LIMITS,
) -> ResumePoint | None:
    """``point`` moved to the device's own last executed segment, or None when the device's
    counters cannot be trusted for it (another boot, the fault cleared since, nothing more
    executed, or the stop fell in a move the host inserted)."""
    done = found.segments_done
    if boot_id != point.boot_id or not found.faulted or point.first_segment <= 0:
        return None
    if done <= point.device_segment:
        return None
    index = done - point.first_segment
    program = items(PlanSpec.from_json(point.plan))
    e_offset = 0.0
    count = 0
    origin = np.asarray(profile.build_volume.bed_origin, dtype=float)
    planned = segment_program(
        program, profile, model, clock_hz=clock_hz, limits=limits, batch_moves=batch_moves
    )
    for out in planned:
        if not isinstance(out, PlannedSegments):
            continue
        if isinstance(program, Restart):
            e_offset = program.e_offset
        if index >= count + len(out):
            count += len(out)
            continue
        k = index - count
        line = int(out.line[k])
        if line == INSERTED_LINE:
            return None
        p = out.point[k]
        g = p - origin
        s = out.steps_abs[k]
        layer = int(out.layer[k]) + 1
        return replace(
            point,
            last_line=line,
            last_layer=layer,
            suggested_layer=max(layer, 1),
            position=(float(p[0]), float(p[1]), float(p[2])),
            point=(float(g[0]), float(g[1]), float(g[2])),
            steps=(int(s[0]), int(s[1]), int(s[2]), int(s[3])),
            e_mm=float(out.e[k]) + e_offset,
            device_segment=done,
        )
    return None
