"""Motion limits a connected device imposes: its announced step rate caps the speeds.

A profile may allow module or filament speeds that need more steps per second than the
device can issue (it announces ``max_step_rate`` in its handshake). Rather than refuse
the file, the host plans the print slower and says so: the caps below keep every axis
under the device's rate with a margin: a segment's peak rate is a little above the
planner's continuous speed, and a microcontroller's step timing degrades near its
limit when several axes step fast at once (the AVR firmware's README gives figures).
"""

from __future__ import annotations

from dataclasses import dataclass

from cdprhost.motion.segments import DEFAULT_LIMITS, MIN_SEGMENT_S, SegmentLimits
from cdprhost.profile.models import MachineProfile

#: plan for at most this fraction of the announced rate
STEP_RATE_MARGIN = 0.9


@dataclass(frozen=True)
class DeviceCaps:
    """The profile to plan with and, when it had to be slowed, what changed (one line);
    the limits the segments keep to (the device's shortest segment and step rate)."""

    profile: MachineProfile
    notice: str | None
    segments: SegmentLimits = DEFAULT_LIMITS


def caps_for_device(
    profile: MachineProfile,
    max_step_rate: float | None,
    min_segment_s: float | None = None,
) -> DeviceCaps:
    """``profile`` with module and extruder speeds capped to ``max_step_rate`` (steps/s
    on any one axis, as the device announced); unchanged when it already fits or the
    device announced nothing. The segments keep to the rate and to the device's
    shortest segment (``min_segment_s``, from its CAPS) after rounding."""
    segments = SegmentLimits(
        max(MIN_SEGMENT_S, min_segment_s or 0.0),
        None if max_step_rate is None else float(max_step_rate),
    )
    if max_step_rate is None:
        return DeviceCaps(profile, None, segments)
    rate = STEP_RATE_MARGIN * float(max_step_rate)
    module_cap = rate / max(profile.drive.steps_per_mm)
    extruder_cap = rate / profile.extruder.steps_per_mm
    motion, extruder = profile.motion, profile.extruder
    said = []
    if motion.module_max_velocity_mm_s > module_cap:
        said.append(
            f"module speed {module_cap:.1f} mm/s (profile {motion.module_max_velocity_mm_s:g})"
        )
        motion = motion.model_copy(update={"module_max_velocity_mm_s": module_cap})
    if extruder.max_velocity_mm_s > extruder_cap:
        said.append(
            f"filament speed {extruder_cap:.1f} mm/s (profile {extruder.max_velocity_mm_s:g})"
        )
        extruder = extruder.model_copy(update={"max_velocity_mm_s": extruder_cap})
    if not said:
        return DeviceCaps(profile, None, segments)
    notice = f"the device steps at most {max_step_rate:g}/s per axis: planned with " + " and ".join(
        said
    )
    slowed = profile.model_copy(update={"motion": motion, "extruder": extruder})
    return DeviceCaps(slowed, notice, segments)
