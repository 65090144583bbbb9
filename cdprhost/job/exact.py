"""The exact place a killed job's device stopped, from the device itself.

A resume point is saved every few seconds; a host that is killed between saves leaves
one a little behind. The device knows better: if it still holds the fault its watchdog
raised for that job (same boot, not cleared since), its ``segments_done`` is the exact
last executed segment. If it has reset since (its watchdog, or the DTR auto-reset of a
Mega when a host opened the port), the BOOT it announced before the new session carries
the counters it kept through the reset (a checksummed record in RAM that survives any
reset but a power loss): the same last executed segment. Planning is deterministic, so
re-planning the dead job's program and counting from its first segment names that
segment's G-code line, point and filament position.

When the device has restarted and kept no record (a power loss), or its record is not
that job's, the exact place is unknown: ``--resume`` is refused, naming the layer to
restart from (``--resume-from-layer``, which re-homes and reprints the layer).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cdprhost.errors import CdprError
from cdprhost.job.resume import SAVED_WHILE_PRINTING, ResumePoint
from cdprhost.job.resume_items import INSERTED_LINE, PlanSpec
from cdprhost.kinematics.machine import MachineModel
from cdprhost.link import DeviceStatus
from cdprhost.link.tracker import boot_cause_text
from cdprhost.motion.pipeline import segment_program
from cdprhost.motion.segments import DEFAULT_LIMITS, PlannedSegments, SegmentLimits
from cdprhost.profile.models import MachineProfile
from firmware_protocol.codes import BootCause
from firmware_protocol.messages import Boot


class ExactPlaceUnknown(CdprError):
    """``--resume`` of a point the device cannot confirm: it restarted without a record."""


@dataclass(frozen=True)
class DeviceStop:
    """The device's own last executed segment of the point's job."""

    segment: int
    reset: str = ""  # the reset since the point was saved, in words ("": none)


def reset_notice(boot: Boot | None) -> str:
    """What a connect says of a reset the device announced (BOOT before the session): its
    cause and what it kept; "" after a power-on or without a BOOT (no reset since its last
    session)."""
    if boot is None or boot.cause == BootCause.POWER_ON:
        return ""
    kept = (
        f"it kept its record (last executed segment {boot.prev_segments_done}) and held the "
        "drivers it had enabled"
        if boot.prev_valid
        else "it kept no record (its RAM did not survive)"
    )
    return f"the device reset before this connect ({boot_cause_text(boot.cause)}); {kept}"


def device_stop(
    point: ResumePoint, found: DeviceStatus, boot_id: int, boot: Boot | None
) -> DeviceStop | None:
    """Where the device stopped the job that saved ``point``: its own counters (``found``, the
    status at connect, on the same boot) or the record its BOOT announced after a reset
    (``boot``, heard at this connect). None when the device knows nothing newer than the
    point. Raises ExactPlaceUnknown when the point was written while printing (a killed
    host: maybe behind the device), the device restarted since and kept no record."""
    # a BOOT heard at connect means no session since that boot, so not the point's session
    # (the same id again is a collision: a board whose EEPROM boot count was not kept)
    if boot_id == point.boot_id and boot is None:
        done = found.segments_done
        return DeviceStop(done) if found.faulted and done > point.device_segment else None
    if point.reason != SAVED_WHILE_PRINTING or not point.boot_id:
        return None  # the host's own last point of the job: exact as it is
    layer = point.suggested_layer or point.last_layer or 1
    restart = (
        f"the exact place is unknown; restart from the start of layer {layer} with "
        f"--resume-from-layer {layer} (the machine re-homes and reprints that layer)"
    )
    if boot is None:
        raise ExactPlaceUnknown(
            f"--resume: the device has restarted since the print stopped (boot id "
            f"{point.boot_id:#010x} -> {boot_id:#010x}) and its record of the last executed "
            f"segment was not read (another program has connected since): {restart}"
        )
    if not boot.prev_valid:
        raise ExactPlaceUnknown(
            f"--resume: the device restarted since the print stopped "
            f"({boot_cause_text(boot.cause)}) and kept no record of its last executed segment "
            f"(a power loss clears it): {restart}"
        )
    if boot.prev_segments_done < point.device_segment:
        raise ExactPlaceUnknown(
            f"--resume: the device's record names segment {boot.prev_segments_done}, before "
            f"the resume point's {point.device_segment}: it has restarted more than once since "
            f"the print stopped, and the record is of a later boot: {restart}"
        )
    return DeviceStop(boot.prev_segments_done, boot_cause_text(boot.cause))


def refine_point(
    point: ResumePoint,
    done: int,
    items: Callable[[PlanSpec], Iterable[Any]],
    profile: MachineProfile,
    model: MachineModel,
    *,
    clock_hz: int,
    batch_moves: int,
    limits: SegmentLimits = DEFAULT_LIMITS,
) -> ResumePoint | None:
    """``point`` moved to the device's last executed segment ``done`` (its own numbering, as
    the point's), or None when it cannot be placed (the job's first segment unknown, or
    the stop fell in a move the host inserted). ``done`` equal to the point's segment gives
    the point itself."""
    if point.first_segment <= 0:
        return None
    if done == point.device_segment:
        return point
    index = done - point.first_segment
    if index < 0:
        return None
    program = items(PlanSpec.from_json(point.plan))
    count = 0
    origin = np.asarray(profile.build_volume.bed_origin, dtype=float)
    planned = segment_program(
        program, profile, model, clock_hz=clock_hz, limits=limits, batch_moves=batch_moves
    )
    for out in planned:
        if not isinstance(out, PlannedSegments):
            continue
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
            e_mm=float(out.e[k]),  # the file's absolute E (a restart keeps it)
            device_segment=done,
        )
    return None
