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

from cdprhost.profile.models import MachineProfile, PidGains

FULL_STEPS = 200
MICROSTEPS = 16
_PINS = (
    ("PF0", "PF1", "!PD7"),
    ("PF6", "PF7", "!PF2"),
    ("PL3", "PL1", "!PK0"),
)
_EXTRUDER_PINS = ("PA4", "PA6", "!PA2")  # RAMPS E0
# RAMPS 1.4 as our firmware wires it (firmware/src/board_ramps14.h): hotend MOSFET D10,
# bed D8, fan D9; thermistors on A13 (hotend) and A14 (bed), 100k NTC beta 3950 with the
# board's 4.7k pull-up, which is Klipper's "Generic 3950" (its default pull-up is 4.7k)
_HOTEND_PINS = ("PB4", "PK5")
_BED_PINS = ("PH5", "PK6")
_FAN_PIN = "PH6"
SENSOR_TYPE = "Generic 3950"
NOZZLE_MM = 0.4  # the profile names no nozzle: the common one (change it for another)
# Klipper's example gains for a RAMPS hotend (config/generic-ramps.cfg), used until the
# profile holds tuned ones (`M303`; in Klipper, PID_CALIBRATE)
_DEFAULT_HOTEND_PID = (22.2, 1.08, 114.0)

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
    m = profile.motion
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
        f"# lengths {_vec(winch.home_lengths)} mm. set_position_* declares it (no",
        "# SET_KINEMATIC_POSITION: that needs [force_move] enable_force_move, off by default);",
        "# the G-code only waits for the moves before it.",
        "[homing_override]",
        "axes: xyz",
        f"set_position_x: {hx:.6f}",
        f"set_position_y: {hy:.6f}",
        f"set_position_z: {hz:.6f}",
        "gcode:",
        "  M400",
        "",
        *_extruder(profile),
        "",
        *_bed(profile),
        "",
        "# the part cooling fan (RAMPS D9): M106/M107",
        "[fan]",
        f"pin: {_FAN_PIN}",
        "",
    ]
    return "\n".join(out)


def _pid(gains: PidGains | None, default: tuple[float, float, float] | None) -> list[str]:
    """Klipper's ``control`` lines: the profile's gains (Marlin's units, as Klipper's), else
    ``default``, else bang-bang (``watermark``)."""
    if gains is not None:
        kp, ki, kd = gains.kp, gains.ki, gains.kd
    elif default is not None:
        kp, ki, kd = default
    else:
        return ["control: watermark"]
    return ["control: pid", f"pid_Kp: {kp:g}", f"pid_Ki: {ki:g}", f"pid_Kd: {kd:g}"]


def _extruder(profile: MachineProfile) -> list[str]:
    ex, heaters = profile.extruder, profile.heaters
    step, direction, enable = _EXTRUDER_PINS
    heater, sensor = _HOTEND_PINS
    tuned = "the profile's gains" if heaters.hotend_pid else "Klipper's RAMPS example gains"
    return [
        f"# the extruder and hotend (RAMPS E0, D10, A13); PID: {tuned} (PID_CALIBRATE tunes them)",
        "[extruder]",
        f"step_pin: {step}",
        f"dir_pin: {direction}",
        f"enable_pin: {enable}",
        f"microsteps: {MICROSTEPS}",
        f"full_steps_per_rotation: {FULL_STEPS}",
        f"rotation_distance: {FULL_STEPS * MICROSTEPS / ex.steps_per_mm:.9g}",
        f"nozzle_diameter: {NOZZLE_MM:g}  # the profile names none: change it for another",
        f"filament_diameter: {ex.filament_diameter_mm:g}",
        f"max_extrude_only_velocity: {ex.max_velocity_mm_s:g}",
        f"max_extrude_only_accel: {ex.max_accel_mm_s2:g}",
        # a first layer's wide lines exceed Klipper's default (4 nozzle^2); loading and
        # priming exceed its 50 mm extrude-only default
        f"max_extrude_cross_section: {10 * NOZZLE_MM**2:g}",
        "max_extrude_only_distance: 200",
        f"heater_pin: {heater}",
        f"sensor_type: {SENSOR_TYPE}",
        f"sensor_pin: {sensor}",
        *_pid(heaters.hotend_pid, _DEFAULT_HOTEND_PID),
        "min_temp: 0",
        f"max_temp: {heaters.hotend_max_c:g}",
    ]


def _bed(profile: MachineProfile) -> list[str]:
    heater, sensor = _BED_PINS
    pid = profile.heaters.bed_pid
    how = "the profile's PID gains" if pid else "bang-bang (PID_CALIBRATE HEATER=heater_bed)"
    return [
        f"# the heated bed (RAMPS D8, A14): {how}",
        "[heater_bed]",
        f"heater_pin: {heater}",
        f"sensor_type: {SENSOR_TYPE}",
        f"sensor_pin: {sensor}",
        *_pid(pid, None),
        "min_temp: 0",
        f"max_temp: {profile.heaters.bed_max_c:g}",
    ]


def _bullets(lines: Sequence[str]) -> list[str]:
    out: list[str] = []
    for line in lines:
        wrapped = textwrap.wrap(line, 84, break_on_hyphens=False)
        out += [f"#  - {wrapped[0]}", *(f"#    {w}" for w in wrapped[1:])]
    return out


def _vec(v: Sequence[float] | np.ndarray) -> str:
    return "(" + ", ".join(f"{float(x):g}" for x in v) + ")"
