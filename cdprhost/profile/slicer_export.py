"""Slicer printer definitions from a machine profile (``profile export-slicer``).

So that files are sliced for this machine from the start: the bed is the build
triangle (a polygon, origin at its centre, as the G-code frame has it), the
height is what the whole triangle can reach, the limits are the profile's, the
start and end G-code are the profile's (its ``{hotend_c}``/``{bed_c}`` become the
slicer's own placeholders), and the slicer retracts with the profile's length and
speeds. The slicer writes those retractions as moves (``G1 E-...``), not as firmware
retraction (G10/G11, which the host still prints): the slicers' time estimates leave
G10/G11 out, and on a part with many retractions that alone put the slicer's estimate
2 % under ours; with the moves in the file and the limits here, the slicer's estimate
is within 1 % of ``check``'s on the examples. The caller computes the printable bed (it
needs the kinematics); everything here is text.

- PrusaSlicer (and SuperSlicer): a printer ``.ini`` (File > Import > Import Config,
  or ``prusa-slicer --load``).
- Cura: a machine definition ``.def.json`` inheriting ``fdmprinter``, for the
  ``definitions`` folder; the rectangle around the triangle is the bed and the
  rest is ``machine_disallowed_areas`` (Cura's bed-centred coordinates, Y flipped).
- OrcaSlicer: a user machine preset ``.json`` (``printable_area`` is the triangle).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Literal

from cdprhost.profile.models import MachineProfile

Slicer = Literal["prusaslicer", "cura", "orca"]
Polygon = Sequence[tuple[float, float]]
SLICERS: tuple[Slicer, ...] = ("prusaslicer", "cura", "orca")
NOZZLE_MM = 0.4

# the slicers' names for the first-layer temperatures
_PLACEHOLDERS = {
    "prusaslicer": ("[first_layer_temperature]", "[first_layer_bed_temperature]"),
    "cura": ("{material_print_temperature_layer_0}", "{material_bed_temperature_layer_0}"),
    "orca": ("[nozzle_temperature_initial_layer]", "[bed_temperature_initial_layer_single]"),
}


def slicer_gcode(profile: MachineProfile, which: Literal["start", "end"], slicer: Slicer) -> str:
    """The profile's start or end G-code with the slicer's temperature placeholders."""
    hotend, bed = _PLACEHOLDERS[slicer]
    text = profile.gcode.start if which == "start" else profile.gcode.end
    return (
        text.replace("{hotend_c}", hotend)
        .replace("{bed_c}", bed)
        .replace("{{", "{")
        .replace("}}", "}")
    )


def export(
    profile: MachineProfile,
    slicer: Slicer,
    polygon: Polygon,
    height_mm: float,
) -> str:
    """The definition text for ``slicer``; ``polygon``: the printable bed, G-code frame."""
    if slicer == "prusaslicer":
        return _prusaslicer(profile, polygon, height_mm)
    if slicer == "cura":
        return _cura(profile, polygon, height_mm)
    return _orca(profile, polygon, height_mm)


def _limits(profile: MachineProfile) -> dict[str, float]:
    m, ex = profile.motion, profile.extruder
    accel = min(m.max_accel_mm_s2, profile.statics.a_max_mm_s2 or m.max_accel_mm_s2)
    return {
        "velocity": m.max_velocity_mm_s,
        "z_velocity": min(m.max_velocity_mm_s, m.module_max_velocity_mm_s),
        "accel": accel,
        "corner": m.square_corner_velocity_mm_s,
        "e_velocity": ex.max_velocity_mm_s,
        "e_accel": ex.max_accel_mm_s2,
    }


def _header(profile: MachineProfile, comment: str) -> str:
    return (
        f"{comment} cdprhost printer definition for profile '{profile.name}' "
        f"(cdprhost profile export-slicer); G-code origin: the build triangle's centre\n"
    )


def _prusaslicer(profile: MachineProfile, polygon: Polygon, height: float) -> str:
    lim = _limits(profile)
    ex = profile.extruder
    pairs = {
        "printer_technology": "FFF",
        "printer_settings_id": f"cdprhost {profile.name}",
        "printer_notes": f"cdprhost profile {profile.name}",
        "bed_shape": ",".join(f"{x:g}x{y:g}" for x, y in polygon),
        "max_print_height": f"{height:g}",
        "z_offset": "0",
        "gcode_flavor": "marlin2",
        "use_relative_e_distances": "1",
        "use_firmware_retraction": "0",
        "retract_length": f"{ex.retract_mm:g}",
        "retract_speed": f"{ex.retract_speed_mm_s:g}",
        "deretract_speed": f"{ex.unretract_speed_mm_s:g}",
        "retract_restart_extra": f"{ex.unretract_extra_mm:g}",
        "retract_lift": "0",
        "wipe": "0",
        "nozzle_diameter": f"{NOZZLE_MM:g}",
        "filament_diameter": f"{ex.filament_diameter_mm:g}",
        "machine_limits_usage": "time_estimate_only",
        "machine_max_feedrate_x": f"{lim['velocity']:g}",
        "machine_max_feedrate_y": f"{lim['velocity']:g}",
        "machine_max_feedrate_z": f"{lim['z_velocity']:g}",
        "machine_max_feedrate_e": f"{lim['e_velocity']:g}",
        "machine_max_acceleration_x": f"{lim['accel']:g}",
        "machine_max_acceleration_y": f"{lim['accel']:g}",
        "machine_max_acceleration_z": f"{lim['accel']:g}",
        "machine_max_acceleration_e": f"{lim['e_accel']:g}",
        "machine_max_acceleration_extruding": f"{lim['accel']:g}",
        "machine_max_acceleration_retracting": f"{lim['e_accel']:g}",
        "machine_max_acceleration_travel": f"{lim['accel']:g}",
        "machine_max_jerk_x": f"{lim['corner']:g}",
        "machine_max_jerk_y": f"{lim['corner']:g}",
        "machine_max_jerk_z": f"{lim['corner']:g}",
        "machine_max_jerk_e": "5",
        "start_gcode": _escaped(slicer_gcode(profile, "start", "prusaslicer")),
        "end_gcode": _escaped(slicer_gcode(profile, "end", "prusaslicer")),
        "before_layer_gcode": "",
        "layer_gcode": "G92 E0",  # relative E: the slicers ask for a reset every layer
        "gcode_label_objects": "1",
    }
    return _header(profile, "#") + "".join(f"{k} = {v}\n" for k, v in pairs.items())


def _escaped(text: str) -> str:
    return text.rstrip("\n").replace("\\", "\\\\").replace("\n", "\\n")


def _cura(profile: MachineProfile, polygon: Polygon, height: float) -> str:
    lim = _limits(profile)
    ex = profile.extruder
    xs, ys = [p[0] for p in polygon], [p[1] for p in polygon]
    half_w = max(abs(min(xs)), abs(max(xs)))
    half_d = max(abs(min(ys)), abs(max(ys)))
    # everything of the centred rectangle outside the triangle, as polygons in Cura's
    # bed-centred coordinates (Y grows towards the front: the G-code Y flipped)
    disallowed = [
        [[round(x, 3), round(-y, 3)] for x, y in area] for area in _outside(polygon, half_w, half_d)
    ]

    def value(v: object) -> dict[str, object]:
        return {"default_value": v}

    overrides = {
        "machine_name": value(f"cdprhost {profile.name}"),
        "machine_width": value(round(2 * half_w, 3)),
        "machine_depth": value(round(2 * half_d, 3)),
        "machine_height": value(height),
        "machine_center_is_zero": value(True),
        "machine_shape": value("rectangular"),
        "machine_heated_bed": value(True),
        "machine_disallowed_areas": value(disallowed),
        "machine_gcode_flavor": value("RepRap (Marlin/Sprinter)"),
        "machine_start_gcode": value(slicer_gcode(profile, "start", "cura")),
        "machine_end_gcode": value(slicer_gcode(profile, "end", "cura")),
        "machine_nozzle_size": value(NOZZLE_MM),
        "material_diameter": value(ex.filament_diameter_mm),
        "machine_firmware_retract": value(False),
        "retraction_enable": value(ex.retract_mm > 0),
        "retraction_amount": value(ex.retract_mm),
        "retraction_speed": value(ex.retract_speed_mm_s),
        "retraction_retract_speed": value(ex.retract_speed_mm_s),
        "retraction_prime_speed": value(ex.unretract_speed_mm_s),
        "retraction_extra_prime_amount": value(ex.unretract_extra_mm),
        "relative_extrusion": value(True),
        "machine_max_feedrate_x": value(lim["velocity"]),
        "machine_max_feedrate_y": value(lim["velocity"]),
        "machine_max_feedrate_z": value(lim["z_velocity"]),
        "machine_max_feedrate_e": value(lim["e_velocity"]),
        "machine_max_acceleration_x": value(lim["accel"]),
        "machine_max_acceleration_y": value(lim["accel"]),
        "machine_max_acceleration_z": value(lim["accel"]),
        "machine_max_acceleration_e": value(lim["e_accel"]),
        "machine_acceleration": value(lim["accel"]),
        "machine_max_jerk_xy": value(lim["corner"]),
        "machine_max_jerk_z": value(lim["corner"]),
    }
    definition = {
        "version": 2,
        "name": f"cdprhost {profile.name}",
        "inherits": "fdmprinter",
        "metadata": {
            "visible": True,
            "author": "cdprhost profile export-slicer",
            "manufacturer": "cdprhost",
            "file_formats": "text/x-gcode",
            "comment": _header(profile, "").strip(),
        },
        "overrides": overrides,
    }
    return json.dumps(definition, indent=2) + "\n"


def _outside(polygon: Polygon, half_w: float, half_d: float) -> list[list[tuple[float, float]]]:
    """Convex pieces of the rectangle [-w, w] x [-d, d] outside the convex ``polygon``:
    for each edge, the part of the rectangle beyond it (a quadrilateral or triangle)."""
    corners = [(-half_w, -half_d), (half_w, -half_d), (half_w, half_d), (-half_w, half_d)]
    pieces = []
    n = len(polygon)
    for k in range(n):
        (ax, ay), (bx, by) = polygon[k], polygon[(k + 1) % n]
        # outward side of edge a->b for a counter-clockwise polygon: cross < 0
        beyond = [c for c in corners if (bx - ax) * (c[1] - ay) - (by - ay) * (c[0] - ax) < 0]
        if beyond:
            pieces.append(_hull([(ax, ay), (bx, by), *beyond]))
    return pieces


def _hull(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Convex hull, counter-clockwise (a handful of points)."""
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple[float, float]] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def _orca(profile: MachineProfile, polygon: Polygon, height: float) -> str:
    lim = _limits(profile)
    ex = profile.extruder

    def pair(v: float) -> list[str]:  # Orca keeps (normal, silent) mode pairs
        return [f"{v:g}", f"{v:g}"]

    preset = {
        "type": "machine",
        "name": f"cdprhost {profile.name}",
        "from": "User",
        "instantiation": "true",
        "printer_technology": "FFF",
        "printer_settings_id": f"cdprhost {profile.name}",
        "printer_notes": _header(profile, "").strip(),
        "printable_area": [f"{x:g}x{y:g}" for x, y in polygon],
        "printable_height": f"{height:g}",
        "gcode_flavor": "marlin2",
        "use_relative_e_distances": "1",
        "use_firmware_retraction": "0",
        "retraction_length": [f"{ex.retract_mm:g}"],
        "retraction_speed": [f"{ex.retract_speed_mm_s:g}"],
        "deretraction_speed": [f"{ex.unretract_speed_mm_s:g}"],
        "retract_restart_extra": [f"{ex.unretract_extra_mm:g}"],
        "z_hop": ["0"],
        "nozzle_diameter": [f"{NOZZLE_MM:g}"],
        "machine_limits_usage": "time_estimate_only",
        "machine_max_speed_x": pair(lim["velocity"]),
        "machine_max_speed_y": pair(lim["velocity"]),
        "machine_max_speed_z": pair(lim["z_velocity"]),
        "machine_max_speed_e": pair(lim["e_velocity"]),
        "machine_max_acceleration_x": pair(lim["accel"]),
        "machine_max_acceleration_y": pair(lim["accel"]),
        "machine_max_acceleration_z": pair(lim["accel"]),
        "machine_max_acceleration_e": pair(lim["e_accel"]),
        "machine_max_acceleration_extruding": pair(lim["accel"]),
        "machine_max_acceleration_retracting": pair(lim["e_accel"]),
        "machine_max_acceleration_travel": pair(lim["accel"]),
        "machine_max_jerk_x": pair(lim["corner"]),
        "machine_max_jerk_y": pair(lim["corner"]),
        "machine_max_jerk_z": pair(lim["corner"]),
        "machine_max_jerk_e": pair(5.0),
        "machine_start_gcode": slicer_gcode(profile, "start", "orca"),
        "machine_end_gcode": slicer_gcode(profile, "end", "orca"),
        "layer_change_gcode": "G92 E0",
        "gcode_label_objects": "1",
    }
    return json.dumps(preset, indent=4) + "\n"
