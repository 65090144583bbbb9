"""A printer's purge lines in a file without slicer layer markers: `--retarget` finds them
(extrusions outside the part's first layer, ended by an extruder reset), replaces them
with the profile's start G-code and lists them; the file then prints."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from cdprhost.gcode.purge import scan_resets
from cdprhost.motion.prepared import Setup
from cdprhost.preflight import preflight
from cdprhost.preflight.render import render_text

DATA = Path(__file__).resolve().parents[1] / "gcode" / "data" / "thirdparty"


def _without_markers(src: str, tmp_path: Path, marker: str) -> Path:
    """The corpus file with its layer markers removed: the purge has no marker around it."""
    out = tmp_path / src.replace(".gcode", "_nomarkers.gcode")
    lines = (DATA / src).read_text().splitlines(keepends=True)
    out.write_text("".join(ln for ln in lines if not ln.startswith(marker)))
    return out


@pytest.fixture
def ender3(tmp_path):
    # Cura's Ender-3 start G-code: X0.1 and X0.4 from Y20 to Y200, G92 E0; absolute E
    return _without_markers("cura413_ender3_cube.gcode", tmp_path, ";LAYER")


@pytest.fixture
def prusa_ender3(tmp_path):
    # PrusaSlicer's Ender-3 start G-code: prime lines at X2 / X2.3, relative E
    return _without_markers("prusaslicer25_ender3_two_objects_m486.gcode", tmp_path, ";LAYER")


def test_the_purge_makes_the_part_look_as_large_as_the_bed_without_retarget(ender3, proto_profile):
    r = preflight(ender3, proto_profile, setup=Setup(center=True))
    assert r.placement.part_max[1] - r.placement.part_min[1] > 150  # purge and part together


@pytest.mark.parametrize("which", ["ender3", "prusa_ender3"])
def test_check_retarget_replaces_the_purge_lines_and_passes(which, request, proto_profile):
    path = request.getfixturevalue(which)
    r = preflight(path, proto_profile, setup=Setup(retarget=True))
    assert r.ok, r.violations[:3]
    rt = r.retarget
    assert rt is not None and len(rt.purge_lines) == 2
    assert "purge lines" in rt.found_by
    # the part alone is placed: the cube is 12 mm, the two objects ~42 mm
    b = r.print_box_gcode
    assert b is not None and b.max[1] - b.min[1] < 50
    assert r.slicer is not None and r.filament_mm == pytest.approx(r.slicer.filament_mm, rel=0.005)
    text = render_text(r)
    assert "replaced purge lines" in text


def test_the_ender3_purge_lines_are_named_by_line_and_coordinates(ender3, proto_profile):
    r = preflight(ender3, proto_profile, setup=Setup(retarget=True))
    lines = ender3.read_text().splitlines()
    purge = [n for n, ln in enumerate(lines, 1) if "Draw the" in ln]
    assert [int(p.split(":")[0].split()[1]) for p in r.retarget.purge_lines] == purge
    assert "X0.1 Y20 -> X0.1 Y200, 15 mm" in r.retarget.purge_lines[0]
    assert r.retarget.start_lines[1] >= purge[-1] + 1  # the reset after it too


def test_files_with_markers_or_no_purge_report_none(proto_profile):
    names = ("cura413_ender3_cube.gcode", "slic3r13_firmware_retraction_tube.gcode")
    for name in (*names, "simplify3d_style_cube.gcode"):  # the last: a skirt, reset after it
        r = preflight(DATA / name, proto_profile, setup=Setup(retarget=True))
        assert r.ok and r.retarget.purge_lines == []


def test_resets_are_found_with_their_line_numbers(tmp_path):
    f = tmp_path / "r.gcode"
    f.write_text("G1 X1\nG92 E0 ; reset\n; G92 E0 in a comment\ng92 e-1\nG92 X0\nG92.0 E0\n")
    assert scan_resets(str(f)).tolist() == [2, 4, 6]


def test_the_ender3_file_prints_on_the_simulated_device(ender3, tmp_path):
    report = tmp_path / "job.json"
    run = subprocess.run(
        [sys.executable, "-m", "cdprhost", "print", str(ender3), "--profile", "paper-prototype"]
        + ["--retarget", "--yes", "--speedup", "400", "--json", str(report)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "XDG_STATE_HOME": str(tmp_path / "state")},
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert json.loads(report.read_text())["status"] == "completed"
