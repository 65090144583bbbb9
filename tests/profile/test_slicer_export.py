"""`profile export-slicer`: slicer printer definitions from the machine profile."""

from __future__ import annotations

import configparser
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cdprhost.kinematics import MachineModel
from cdprhost.preflight.placement import printable_bed
from cdprhost.profile import load_profile
from cdprhost.profile.slicer_export import export, slicer_gcode

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bed():
    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    return profile, model, printable_bed(model, np.asarray(profile.build_volume.bed_origin))


def test_the_printable_bed_is_the_triangle_and_all_of_it_works(bed):
    profile, model, b = bed
    poly = np.asarray(b.polygon)
    assert poly.shape == (3, 2)
    side = np.linalg.norm(poly[1] - poly[0])
    assert 160 < side < profile.build_volume.side_mm  # the triangle, 1 mm in from its edges
    (ux, uy), (vx, vy) = poly[1] - poly[0], poly[2] - poly[0]
    assert ux * vy - uy * vx > 0  # counter-clockwise, as slicers want
    assert 150 < b.height_mm < profile.build_volume.z_max_mm - profile.build_volume.z_min_mm
    # every point of the bed polygon passes every rule up to that height, not above
    origin = np.asarray(profile.build_volume.bed_origin)
    w = np.linspace(0, 1, 15)
    a, c = np.meshgrid(w, w)
    keep = a + c <= 1
    xy = poly[0] + a[keep][:, None] * (poly[1] - poly[0]) + c[keep][:, None] * (poly[2] - poly[0])
    for z, expected in ((0.0, True), (b.height_mm, True), (b.height_mm + 5.0, False)):
        pts = np.column_stack([xy, np.full(len(xy), z)]) + origin
        assert model.check(pts).ok.all() == expected


def test_prusaslicer_ini(bed):
    profile, _, b = bed
    text = export(profile, "prusaslicer", b.polygon, b.height_mm)
    cp = configparser.ConfigParser(interpolation=None)
    cp.read_string("[printer]\n" + text)
    ini = cp["printer"]
    corners = [tuple(float(v) for v in p.split("x")) for p in ini["bed_shape"].split(",")]
    assert corners == [tuple(p) for p in b.polygon]
    assert float(ini["max_print_height"]) == b.height_mm
    # the slicer writes the retractions as moves, so its time estimate counts them
    assert ini["use_firmware_retraction"] == "0" and float(ini["retract_length"]) == 1.0
    assert float(ini["retract_speed"]) == 35.0
    assert float(ini["machine_max_acceleration_x"]) == 2000.0
    start = ini["start_gcode"].replace("\\n", "\n")
    assert "M104 S[first_layer_temperature]" in start and "G28" in start
    assert "{hotend_c}" not in start


def test_cura_definition(bed):
    profile, _, b = bed
    d = json.loads(export(profile, "cura", b.polygon, b.height_mm))
    o = {k: v["default_value"] for k, v in d["overrides"].items()}
    assert d["inherits"] == "fdmprinter" and o["machine_center_is_zero"] is True
    assert o["machine_width"] >= 2 * 83.268 and o["machine_depth"] >= 2 * 96.15
    assert len(o["machine_disallowed_areas"]) == 3  # the rectangle minus the triangle
    assert "{material_print_temperature_layer_0}" in o["machine_start_gcode"]
    assert o["machine_firmware_retract"] is False and o["retraction_enable"] is True


def test_orca_preset(bed):
    profile, _, b = bed
    d = json.loads(export(profile, "orca", b.polygon, b.height_mm))
    assert d["type"] == "machine" and d["printable_area"] == [f"{x:g}x{y:g}" for x, y in b.polygon]
    assert "[nozzle_temperature_initial_layer]" in d["machine_start_gcode"]


def test_literal_braces_in_the_profile_gcode_survive():
    profile = load_profile("paper-prototype")
    gc = profile.gcode.model_copy(update={"start": "M117 {{hello}}\nM104 S{hotend_c}\n"})
    p = profile.model_copy(update={"gcode": gc})
    assert (
        slicer_gcode(p, "start", "prusaslicer") == "M117 {hello}\nM104 S[first_layer_temperature]\n"
    )


@pytest.mark.parametrize("slicer", ["prusaslicer", "cura", "orca"])
def test_cli_writes_the_file(tmp_path, slicer):
    out = tmp_path / f"cdpr.{slicer}"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cdprhost",
            "profile",
            "export-slicer",
            "paper-prototype",
            "--to",
            slicer,
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert out.stat().st_size > 500 and "bed triangle" in r.stdout


def test_the_example_in_the_repository_was_sliced_with_the_exported_profile():
    ini = (ROOT / "examples" / "paper-prototype.prusaslicer.ini").read_text()
    profile = load_profile("paper-prototype")
    model = MachineModel.from_profile(profile)
    b = printable_bed(model, np.asarray(profile.build_volume.bed_origin))
    assert ini == export(profile, "prusaslicer", b.polygon, b.height_mm)
    gcode = (ROOT / "examples" / "example.gcode").read_text()
    assert (
        "; generated by PrusaSlicer" in gcode
        and "printer_notes = cdprhost profile paper-prototype" in gcode
    )
