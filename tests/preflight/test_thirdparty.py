"""Files sliced by others for other printers (tests/gcode/data/thirdparty, see its README):
they read, pass `check --retarget`, and their figures match the slicer's."""

from __future__ import annotations

from pathlib import Path

import pytest

from cdprhost.motion.prepared import Setup
from cdprhost.preflight import preflight
from cdprhost.preflight.render import render_text

DATA = Path(__file__).resolve().parents[1] / "gcode" / "data" / "thirdparty"
FILES = sorted(DATA.glob("*.gcode"))
WHOLE = [f for f in FILES if "cropped" not in f.name]  # the slicer's figures are for these


def test_the_corpus_is_there():
    names = {f.name for f in FILES}
    assert len(names) >= 8
    for slicer in ("prusaslicer25", "slic3r13", "cura413", "simplify3d"):
        assert any(n.startswith(slicer) for n in names)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_files_for_other_printers_pass_check_retarget(path, proto_profile):
    r = preflight(path, proto_profile, setup=Setup(retarget=True))
    assert r.ok, r.violations[:3]
    assert r.retarget is not None and r.retarget.start_lines is not None
    assert r.retarget.end_lines is not None
    assert r.retarget.hotend_c > 0 and r.retarget.bed_c > 0
    # nothing of the other printer's start block is left: no move before the part's layers
    assert r.print_box_gcode is not None and r.print_box_gcode.min[2] > 0.0
    assert r.warnings_total == 0 or all(w.word in ("PRINT_START", "PRINT_END") for w in r.warnings)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_files_sliced_for_other_printers_are_refused_with_placement_advice(path, proto_profile):
    r = preflight(path, proto_profile)
    assert not r.ok  # their own start blocks and bed coordinates cannot fit this machine
    p = r.placement
    assert p is not None and p.part_min is not None and p.allowed is not None
    assert p.fit_offset is not None  # every part here fits once moved
    # the part moved by the proposed offset lies in the allowed region's box
    dx, dy = p.fit_offset
    assert p.allowed.x[0] <= p.part_min[0] + dx and p.part_max[0] + dx <= p.allowed.x[1]
    assert p.allowed.y[0] <= p.part_min[1] + dy and p.part_max[1] + dy <= p.allowed.y[1]


@pytest.mark.parametrize("path", WHOLE, ids=lambda p: p.stem)
def test_filament_matches_the_slicer_within_half_a_percent(path, proto_profile):
    for setup in (Setup(), Setup(retarget=True)):
        r = preflight(path, proto_profile, setup=setup)
        assert r.slicer is not None and r.slicer.filament_mm is not None
        assert r.filament_mm == pytest.approx(r.slicer.filament_mm, rel=0.005)


def test_arc_boat_prints_with_center(proto_profile):
    path = DATA / "slic3r13_arcs_boat.gcode"
    arcs = sum(1 for line in open(path) if line.startswith(("G2 ", "G3 ")))
    assert arcs > 3700
    r = preflight(path, proto_profile, setup=Setup(center=True))
    assert r.ok, r.violations[:3]
    assert r.placement.offset == pytest.approx((-99.46, -100.0), abs=0.01)


def test_offset_shifts_like_center(proto_profile):
    path = DATA / "slic3r13_firmware_retraction_tube.gcode"
    centred = preflight(path, proto_profile, setup=Setup(center=True))
    by_hand = preflight(path, proto_profile, setup=Setup(offset=centred.placement.offset))
    assert by_hand.ok and by_hand.print_box_gcode == centred.print_box_gcode
    assert by_hand.estimated_time_s == pytest.approx(centred.estimated_time_s, rel=1e-9)


def test_klipper_macros_are_warnings_and_strict_makes_them_errors(proto_profile):
    path = DATA / "prusaslicer25_voron_klipper_exclude_object.gcode"
    r = preflight(path, proto_profile, setup=Setup(center=True))
    assert r.ok and {w.word for w in r.warnings} == {"PRINT_START", "PRINT_END"}
    assert r.objects == ["CUBE_SMALL_STL", "TUBE_STL"]
    strict = preflight(path, proto_profile, setup=Setup(center=True), strict=True)
    assert not strict.ok and strict.violations_by_rule == {"unknown_command": 2}


def test_cancelling_an_object_removes_its_filament(proto_profile):
    path = DATA / "prusaslicer25_ender3_two_objects_m486.gcode"
    full = preflight(path, proto_profile, setup=Setup(retarget=True))
    assert full.objects == ["0", "1"]
    assert full.object_labels == {"0": "cube_small_stl", "1": "tube_stl"}  # shown by check
    assert 'objects (2; --cancel-object NAME skips one): 0 "cube_small_stl", 1 "tube_stl"' in (
        render_text(full)
    )
    less = preflight(path, proto_profile, setup=Setup(retarget=True, cancel_objects=("1",)))
    by_label = preflight(
        path, proto_profile, setup=Setup(retarget=True, cancel_objects=("tube_stl",))
    )
    assert less.ok and less.cancelled_objects == ["1"]
    assert 0.2 * full.filament_mm < less.filament_mm < 0.8 * full.filament_mm
    assert by_label.filament_mm == pytest.approx(less.filament_mm)


def test_file_limits_slow_the_estimate(proto_profile, tmp_path):
    """M204 was skipped as harmless: a file asking for 500 mm/s^2 now plans slower."""
    path = DATA / "slic3r13_firmware_retraction_tube.gcode"
    slow = tmp_path / "slow.gcode"
    slow.write_text("M204 S500\nM205 X2 Y2\n" + path.read_text())
    fast = preflight(path, proto_profile, setup=Setup(center=True))
    limited = preflight(slow, proto_profile, setup=Setup(center=True))
    assert limited.estimated_time_s > 1.05 * fast.estimated_time_s
