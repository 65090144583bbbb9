"""One straight move from where the device is to a target, as wire segments (jog screen)."""

from __future__ import annotations

from cdprhost.kinematics import MachineModel
from cdprhost.motion.direct import direct_path, state_at_steps
from cdprhost.profile import MachineProfile
from firmware_protocol.segments import SegmentBatch as WireBatch


def straight_move(
    profile: MachineProfile,
    model: MachineModel,
    steps: tuple[int, int, int, int],
    target: tuple[float, float, float],
    *,
    feedrate_mm_s: float,
    clock_hz: int,
) -> tuple[WireBatch, float]:
    """Segments that take the effector from absolute ``steps`` to ``target`` (machine frame), and their duration."""
    wire, seconds, _ = direct_path(
        profile,
        model,
        state_at_steps(model, steps),
        [target],
        feedrate_mm_s=feedrate_mm_s,
        clock_hz=clock_hz,
    )
    return wire, seconds
