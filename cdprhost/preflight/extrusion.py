"""Extrusion sanity: cold extrusion, volumetric flow, heater targets.

- ``cold_extrusion``: filament pushed forward while the hotend target is unset or
  below the minimum extrusion temperature (default 170 C, as common firmware);
- ``volumetric_flow``: filament cross-section x filament speed at the move's planned
  cruise speed above the limit (default 25 mm^3/s); extrude-only moves (priming
  after a retraction) are not melt flow and are not counted;
- ``temperature``: a target above the profile's heater maximum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cdprhost.gcode.items import SetTemperature
from cdprhost.motion.moves import MoveBlock
from cdprhost.motion.trapezoid import PlannedMoves
from cdprhost.profile.models import MachineProfile

MIN_EXTRUDE_TEMP_C = 170.0
MAX_FLOW_MM3_S = 25.0


@dataclass(frozen=True)
class ExtrusionLimits:
    filament_area_mm2: float
    min_extrude_temp_c: float = MIN_EXTRUDE_TEMP_C
    max_flow_mm3_s: float = MAX_FLOW_MM3_S
    hotend_max_c: float = 285.0
    bed_max_c: float = 120.0

    @classmethod
    def from_profile(
        cls,
        profile: MachineProfile,
        *,
        min_extrude_temp_c: float = MIN_EXTRUDE_TEMP_C,
        max_flow_mm3_s: float = MAX_FLOW_MM3_S,
    ) -> ExtrusionLimits:
        d = profile.extruder.filament_diameter_mm
        return cls(
            math.pi * d * d / 4.0,
            min_extrude_temp_c,
            max_flow_mm3_s,
            profile.heaters.hotend_max_c,
            profile.heaters.bed_max_c,
        )


def cold_extrusion(
    block: MoveBlock, hotend_target_c: float | None, limits: ExtrusionLimits
) -> tuple[int, int] | None:
    """(index of the first forward extrusion, how many) when the hotend is too cold, else None."""
    if hotend_target_c is not None and hotend_target_c >= limits.min_extrude_temp_c:
        return None
    idx = np.flatnonzero(block.extrusion > 0)
    return (int(idx[0]), int(idx.size)) if idx.size else None


def cold_detail(
    block: MoveBlock, first: int, count: int, hotend_target_c: float | None, limits: ExtrusionLimits
) -> str:
    target = "unset" if hotend_target_c is None else f"{hotend_target_c:g} C"
    more = f"; {count - 1} more extruding move(s) follow at that target" if count > 1 else ""
    return (
        f"extrudes {float(block.extrusion[first]):.4g} mm of filament with the hotend target {target} "
        f"(minimum {limits.min_extrude_temp_c:g} C){more}"
    )


def volumetric_flow(planned: PlannedMoves, limits: ExtrusionLimits) -> np.ndarray:
    """Melt flow at each move's cruise speed (mm^3/s); 0 for travel and extrude-only moves."""
    de = planned.moves.extrusion
    forward = planned.kinematic & (de > 0)
    ratio = np.where(forward, de / np.where(planned.kinematic, planned.length, 1.0), 0.0)
    return ratio * planned.v_cruise * limits.filament_area_mm2


def temperature_problem(cmd: SetTemperature, limits: ExtrusionLimits) -> str | None:
    top = limits.hotend_max_c if cmd.heater == "hotend" else limits.bed_max_c
    if cmd.target_c > top:
        return f"{cmd.heater} target {cmd.target_c:g} C exceeds the heater maximum {top:g} C by {cmd.target_c - top:g} C"
    return None
