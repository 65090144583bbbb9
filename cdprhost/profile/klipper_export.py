"""A Klipper configuration for this machine (``profile export-firmware --to klipper``).

Text only: the numbers come from the kinematics (``cdprhost.kinematics.winch``), which
says how the profile maps onto Klipper's ``winch`` kinematics and what that leaves out.
The stepper pins are RAMPS 1.4's X, Y, Z sockets (modules 1, 2, 3), as our firmware
wires them; ``full_steps_per_rotation`` and ``microsteps`` only have to multiply to
the step count the profile's ``steps_per_mm`` was computed for, ``rotation_distance``
then carries the rest.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from cdprhost.profile.models import MachineProfile

FULL_STEPS = 200
MICROSTEPS = 16
_PINS = (
    ("PF0", "PF1", "!PD7"),
    ("PF6", "PF7", "!PF2"),
    ("PL3", "PL1", "!PK0"),
)
_EXTRUDER_PINS = ("PA4", "PA6", "!PA2")

#: what Klipper's winch kinematics does not do that cdprhost does, whatever the profile
NOT_IN_KLIPPER = (
    (
        "the workspace check before a move (cable tension under a_max, slider travel, the "
        "build triangle): Klipper's winch kinematics checks no boundary; run "
        "`cdprhost check FILE --profile P` on every file first"
    ),
    (
        "the per-module speed and acceleration limits (module_max_velocity_mm_s, "
        "module_max_accel_mm_s2): Klipper limits the toolhead only"
    ),
    (
        "homing: Klipper's winch kinematics cannot home; bring the sliders to their "
        "endstops (or the marks of home_mm) before G28, which only declares the position"
    ),
)


class WinchNumbers(Protocol):
    @property
    def anchors(self) -> np.ndarray: ...
    @property
    def step_distance(self) -> np.ndarray: ...
    @property
    def home(self) -> np.ndarray: ...
    @property
    def home_lengths(self) -> np.ndarray: ...


class Dropped(Protocol):
    @property
    def name(self) -> str: ...
    @property
    def rms_mm(self) -> float: ...
    @property
    def max_mm(self) -> float: ...
    @property
    def note(self) -> str: ...


def dropped_lines(dropped: Sequence[Dropped]) -> list[str]:
    """One line per calibrated effect the config cannot express (for the file and terminal)."""
    return [
        f"{d.name}: not expressed; position error {d.rms_mm * 1000:.0f} um rms, "
        f"{d.max_mm * 1000:.0f} um max ({d.note})"
        for d in dropped
    ]


def klipper_config(profile: MachineProfile, winch: WinchNumbers, dropped: Sequence[Dropped]) -> str:
    m, ex = profile.motion, profile.extruder
    out = [
        f"# Klipper configuration for the cable robot of cdprhost profile '{profile.name}'",
        "# (cdprhost profile export-firmware --to klipper). Klipper's winch kinematics:",
        "# each stepper position is the straight distance from its anchor to the toolhead.",
        (
            "# Anchors are the profile's outlets A_k minus bed_origin "
            f"{_vec(profile.build_volume.bed_origin)}, i.e. in the"
        ),
        "# G-code frame Klipper's toolhead uses; rotation_distance carries steps_per_mm",
        "# and any drive_scale.",
        "#",
        "# What this config cannot express:",
        *_bullets([*dropped_lines(dropped), *NOT_IN_KLIPPER]),
        "",
        "[mcu]",
        "serial: /dev/ttyACM0  # the Arduino Mega 2560 with Klipper's firmware",
        "",
        "[printer]",
        "kinematics: winch",
        f"max_velocity: {m.max_velocity_mm_s:g}",
        f"max_accel: {m.max_accel_mm_s2:g}",
        f"square_corner_velocity: {m.square_corner_velocity_mm_s:g}",
    ]
    spm = profile.drive.steps_per_mm
    for k in range(3):
        step, direction, enable = _PINS[k]
        rotation = float(winch.step_distance[k]) * FULL_STEPS * MICROSTEPS
        out += [
            "",
            (
                f"# module {k + 1}: steps_per_mm {spm[k]:g}; at home the cable is "
                f"{winch.home_lengths[k]:.6f} mm long"
            ),
            f"[stepper_{'abc'[k]}]",
            f"step_pin: {step}",
            f"dir_pin: {direction}",
            f"enable_pin: {enable}",
            f"full_steps_per_rotation: {FULL_STEPS}",
            f"microsteps: {MICROSTEPS}",
            f"rotation_distance: {rotation:.12g}",
            *(f"anchor_{axis}: {winch.anchors[k][j]:.6f}" for j, axis in enumerate("xyz")),
        ]
    hx, hy, hz = (float(v) for v in winch.home)
    out += [
        "",
        "# G28 declares the home point (G-code frame): where the toolhead is when the",
        "# sliders sit at their endstops; the stepper positions are then the cable",
        f"# lengths {_vec(winch.home_lengths)} mm.",
        "[homing_override]",
        "axes: xyz",
        f"set_position_x: {hx:.6f}",
        f"set_position_y: {hy:.6f}",
        f"set_position_z: {hz:.6f}",
        "gcode:",
        f"  SET_KINEMATIC_POSITION X={hx:.6f} Y={hy:.6f} Z={hz:.6f}",
        "",
        "# The extruder (RAMPS E0); add its heater and sensor, then uncomment:",
        "#[extruder]",
        f"#step_pin: {_EXTRUDER_PINS[0]}",
        f"#dir_pin: {_EXTRUDER_PINS[1]}",
        f"#enable_pin: {_EXTRUDER_PINS[2]}",
        f"#microsteps: {MICROSTEPS}",
        f"#rotation_distance: {FULL_STEPS * MICROSTEPS / ex.steps_per_mm:.6g}",
        "#nozzle_diameter: 0.4",
        f"#filament_diameter: {ex.filament_diameter_mm:g}",
        f"#max_extrude_only_velocity: {ex.max_velocity_mm_s:g}",
        f"#max_extrude_only_accel: {ex.max_accel_mm_s2:g}",
        "",
    ]
    return "\n".join(out)


def _bullets(lines: Sequence[str]) -> list[str]:
    out: list[str] = []
    for line in lines:
        wrapped = textwrap.wrap(line, 84, break_on_hyphens=False)
        out += [f"#  - {wrapped[0]}", *(f"#    {w}" for w in wrapped[1:])]
    return out


def _vec(v: Sequence[float] | np.ndarray) -> str:
    return "(" + ", ".join(f"{float(x):g}" for x in v) + ")"
