"""Pydantic models of a machine profile: the whole printer as the host sees it.

A profile is validated once at the boundary (TOML on disk); everything inside the
program trusts the typed values. Lengths in mm, forces in N, mass in kg, time in s.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from cdprhost.profile.device_record import DeviceRecord

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Geometry(_Strict):
    """The 12 kinematic parameters: virtual cable outlets A_k and initial lengths L_k0."""

    outlets: tuple[Vec3, Vec3, Vec3] = Field(description="A_1, A_2, A_3 in the base frame (mm)")
    initial_lengths: tuple[Positive, Positive, Positive] = Field(
        description="L_10, L_20, L_30 (mm)"
    )

    @field_validator("outlets")
    @classmethod
    def _not_collinear(cls, outlets: tuple[Vec3, Vec3, Vec3]) -> tuple[Vec3, Vec3, Vec3]:
        a = np.asarray(outlets, dtype=float)
        area2 = float(np.linalg.norm(np.cross(a[1] - a[0], a[2] - a[0])))
        span = float(np.max(np.linalg.norm(a - a.mean(axis=0), axis=1)))
        if area2 <= 1e-6 * max(span, 1.0) ** 2:
            raise ValueError(
                "the three outlets are collinear (or coincide); the forward kinematics has no unique solution"
            )
        return outlets


class Drive(_Strict):
    steps_per_mm: tuple[Positive, Positive, Positive]
    travel_mm: tuple[tuple[Finite, Finite], tuple[Finite, Finite], tuple[Finite, Finite]] = Field(
        description="[s_min, s_max] slider travel per module (mm)"
    )
    home_mm: Vec3 = Field(
        default=(0.0, 0.0, 0.0), description="slider position at the module endstop (mm)"
    )

    @model_validator(mode="after")
    def _travel_ordered(self) -> Drive:
        for k, (lo, hi) in enumerate(self.travel_mm):
            if not lo < hi:
                raise ValueError(
                    f"travel_mm[{k}] must be [min, max] with min < max, got [{lo}, {hi}]"
                )
            if not lo <= self.home_mm[k] <= hi:
                raise ValueError(f"home_mm[{k}] = {self.home_mm[k]} lies outside travel_mm[{k}]")
        return self


class Statics(_Strict):
    spring_rate_n_per_mm: NonNegative = 0.15
    spring_preload_n: Finite = 25.0
    spring_ref_z_mm: Finite = 330.0
    effector_mass_kg: Positive = 0.8
    external_force_n: Vec3 = (0.0, 0.0, 0.0)
    gravity_m_s2: Positive = 9.80665
    tension_min_n: NonNegative = 2.0
    tension_max_n: Positive = 300.0
    a_max_mm_s2: NonNegative = 2000.0

    @model_validator(mode="after")
    def _limits(self) -> Statics:
        if self.tension_min_n >= self.tension_max_n:
            raise ValueError("tension_min_n must be below tension_max_n")
        return self


class BuildVolume(_Strict):
    side_mm: Positive = Field(
        description="side of the equilateral build triangle, one vertex on +y"
    )
    z_min_mm: Finite
    z_max_mm: Finite
    bed_origin: Vec3 = Field(
        default=(0.0, 0.0, 110.0), description="machine point of G-code (0,0,0)"
    )

    @model_validator(mode="after")
    def _z_order(self) -> BuildVolume:
        if not self.z_min_mm < self.z_max_mm:
            raise ValueError("z_min_mm must be below z_max_mm")
        return self


class MotionLimits(_Strict):
    max_velocity_mm_s: Positive = 200.0
    max_accel_mm_s2: Positive = 2000.0
    square_corner_velocity_mm_s: NonNegative = 5.0
    module_max_velocity_mm_s: Positive = 150.0
    module_max_accel_mm_s2: Positive = 3000.0
    chord_tolerance_mm: Positive = 0.01
    max_total_step_rate: Positive | None = Field(
        default=None,
        description="steps/s the three modules and the extruder may take summed (a board "
        "whose axes share one CPU: the AVR's step engine announces it, STEP_BUDGET); "
        "unset: no limit beyond each axis's",
    )

    @property
    def junction_deviation_mm(self) -> float:
        """Klipper's conversion of square_corner_velocity to a junction deviation."""
        v = self.square_corner_velocity_mm_s
        return v * v * (2.0**0.5 - 1.0) / self.max_accel_mm_s2


class Extruder(_Strict):
    steps_per_mm: Positive = 95.5
    filament_diameter_mm: Positive = 1.75
    max_velocity_mm_s: Positive = 120.0
    max_accel_mm_s2: Positive = 5000.0
    # firmware retraction (G10/G11; a file may change it with M207/M208 or SET_RETRACTION)
    retract_mm: NonNegative = Field(default=1.0, description="G10 pulls this much back (mm)")
    retract_speed_mm_s: Positive = 35.0
    unretract_extra_mm: NonNegative = Field(
        default=0.0, description="G11 pushes the retraction back plus this much (mm)"
    )
    unretract_speed_mm_s: Positive = 35.0


DEFAULT_START_GCODE = """G28 ; home: the sliders to their endstops
M140 S{bed_c} ; bed
M104 S{hotend_c} ; hotend
M190 S{bed_c}
M109 S{hotend_c}
G21
G90
M83
G92 E0
"""
DEFAULT_END_GCODE = """M104 S0 ; hotend off
M140 S0 ; bed off
M107
G91
G1 Z10 F600 ; lift
G90
M84
"""


class PrintGcode(_Strict):
    """What the machine does around a print, and where M600 parks.

    ``start``/``end`` replace a file's own start and end blocks (``--retarget``) and
    go into the slicer profiles (``profile export-slicer``). ``{hotend_c}`` and
    ``{bed_c}`` are filled with the file's first temperatures (``--retarget``) or
    the slicer's placeholders (export).
    """

    start: str = DEFAULT_START_GCODE
    end: str = DEFAULT_END_GCODE
    hotend_c: Annotated[float, Field(ge=0, le=400, allow_inf_nan=False)] = Field(
        default=210.0, description="{hotend_c} when the file names no temperature"
    )
    bed_c: Annotated[float, Field(ge=0, le=200, allow_inf_nan=False)] = Field(
        default=60.0, description="{bed_c} when the file names no temperature"
    )
    park_xy_mm: tuple[Finite, Finite] = Field(
        default=(0.0, -30.0), description="M600 park point, machine frame (mm)"
    )
    park_lift_mm: NonNegative = Field(default=10.0, description="M600 lifts this much first")
    park_retract_mm: NonNegative = Field(default=2.0, description="M600 retracts this much")
    travel_speed_mm_s: Positive = Field(default=50.0, description="park and placement travels")

    @field_validator("start", "end")
    @classmethod
    def _placeholders(cls, text: str) -> str:
        try:
            text.format(hotend_c=0, bed_c=0)
        except (KeyError, IndexError, ValueError) as exc:
            raise ValueError(
                f"bad placeholder ({exc}): only {{hotend_c}} and {{bed_c}} are filled in; "
                "write {{ and }} for literal braces"
            ) from None
        return text

    def filled(self, text: str, hotend_c: float | None, bed_c: float | None) -> str:
        """``text`` (``start`` or ``end``) with the temperatures filled in."""
        return text.format(
            hotend_c=f"{self.hotend_c if hotend_c is None else hotend_c:g}",
            bed_c=f"{self.bed_c if bed_c is None else bed_c:g}",
        )


class PidGains(_Strict):
    """Heater PID gains in Marlin's ``M301`` units (output 0..255, degrees C, seconds); found
    by ``M303`` (PID autotune) and sent to the device at every connect."""

    kp: NonNegative
    ki: NonNegative
    kd: NonNegative

    def wire(self) -> tuple[int, int, int]:
        """Thousandths, as ``SET_PID`` carries them."""
        return (round(self.kp * 1000), round(self.ki * 1000), round(self.kd * 1000))


class Heaters(_Strict):
    hotend_max_c: Positive = 285.0
    bed_max_c: Positive = 120.0
    hotend_pid: PidGains | None = Field(
        default=None, description="hotend PID gains (M303 E0 finds them; none: the device's own)"
    )
    bed_pid: PidGains | None = Field(
        default=None, description="bed PID gains (M303 E-1 finds them; none: the device's own)"
    )
    on_failure: Literal["off", "keep"] = Field(
        default="off", description="heater policy when a print fails or the link is lost"
    )
    on_cancel: Literal["off", "keep"] = Field(
        default="off", description="heater policy when a print is cancelled"
    )


class Park(_Strict):
    """Where the effector goes when a print is cancelled (clear of the part)."""

    on_cancel: bool = True
    lift_mm: NonNegative = Field(
        default=10.0, description="straight up from where it stopped, capped at the build volume"
    )


class Serial(_Strict):
    baud: Annotated[int, Field(ge=50, le=10_000_000)] = 250000
    port: str | None = None
    timeout_s: Annotated[float, Field(ge=0.1, le=600, allow_inf_nan=False)] = Field(
        default=2.0, description="seconds without a word from the device before giving up"
    )


class EffectEntry(BaseModel):
    """One catalogue effect: its parameters and (optional) standard errors.

    Kept loosely typed here; each effect module validates its own parameters
    (see ``cdprhost.effects``), so adding an effect needs no change to this file.
    """

    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False)


class MachineProfile(_Strict):
    name: str
    description: str = ""
    geometry: Geometry
    drive: Drive
    statics: Statics = Statics()
    build_volume: BuildVolume
    motion: MotionLimits = MotionLimits()
    extruder: Extruder = Extruder()
    heaters: Heaters = Heaters()
    park: Park = Park()
    serial: Serial = Serial()
    gcode: PrintGcode = PrintGcode()
    effects: dict[str, dict[str, Any]] = Field(default_factory=dict)
    calibration: dict[str, Any] = Field(
        default_factory=dict, description="provenance of a calibrated profile"
    )
    device: DeviceRecord | None = Field(
        default=None, description="the board it drives: plan and estimate for its limits"
    )

    @model_validator(mode="after")
    def _outlets_below_build_volume(self) -> MachineProfile:
        top = max(a[2] for a in self.geometry.outlets)
        if top >= self.build_volume.z_min_mm:
            raise ValueError(
                f"geometry.outlets: the highest outlet (z = {top} mm) is not below the build volume "
                f"(z_min_mm = {self.build_volume.z_min_mm}); the effector must hang above the outlets"
            )
        from cdprhost.effects.registry import (
            validate_effects,
        )  # local: effects import profile types

        validate_effects(self.effects)
        return self

    def with_geometry(self, outlets: Any, initial_lengths: Any, **updates: Any) -> MachineProfile:
        """A copy with new kinematic parameters (used by calibration)."""
        geometry = Geometry.model_validate(
            {
                "outlets": np.asarray(outlets, dtype=float).tolist(),
                "initial_lengths": np.asarray(initial_lengths, dtype=float).tolist(),
            }
        )
        data = self.model_dump()
        data["geometry"] = geometry.model_dump()
        data.update(updates)
        return MachineProfile.model_validate(data)


def with_pid(
    profile: MachineProfile, heater: Literal["hotend", "bed"], gains: PidGains
) -> MachineProfile:
    """A copy with ``heater``'s PID gains (what ``M303`` found)."""
    heaters = profile.heaters.model_copy(update={f"{heater}_pid": gains})
    return profile.model_copy(update={"heaters": heaters})
