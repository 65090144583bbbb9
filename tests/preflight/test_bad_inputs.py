"""Inputs that broke preflight: absurd coordinates, empty and move-less files, line ends."""

from __future__ import annotations

import tracemalloc

import pytest

from cdprhost.gcode import GcodeError
from cdprhost.preflight import preflight

START = "M104 S200\nM109 S200\nG28\nG1 Z5 F600\nG1 X10 Y10 E1 F1200\n"
LIMIT_BYTES = 200 * 2**20


def peak_of(fn):
    tracemalloc.start()
    try:
        result = fn()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("x", ["10000000", "100000000", "99999999999", "1" + "0" * 20])
def test_absurd_coordinates_are_refused_at_bounded_cost(tmp_path, proto_profile, x):
    """Regression: G1 X10000000 took 3.6 GB; X99999999999 ended in a numpy traceback."""
    path = tmp_path / "typo.gcode"
    path.write_text(START + f"G1 X{x} E2\nG1 X20 Y20 E3\n")
    report, peak = peak_of(lambda: preflight(path, proto_profile))
    assert not report.ok
    first = report.violations[0]
    assert first.line == 6 and first.rule == "build_volume"
    assert first.point[0] < 60  # the first failing point: where the move leaves the triangle
    assert peak < LIMIT_BYTES


def test_thousands_of_absurd_moves_and_arcs_stay_bounded(tmp_path, proto_profile):
    lines = [START]
    for i in range(3000):
        lines.append(f"G1 X{(-1) ** i * 1e9:.1f} Y{i * 1e5:.1f} E{i + 2} F3000\n")
        lines.append(f"G1 X0 Y0\nG2 X0 Y0 I{1e3 + 37 * i:.1f} J0 E{i + 2.5}\n")
    path = tmp_path / "absurd.gcode"
    path.write_text("".join(lines))
    report, peak = peak_of(lambda: preflight(path, proto_profile))
    assert not report.ok and report.violations_total >= 3000
    assert len(report.violations) <= 3 * 200  # stored per rule; the rest are counted
    assert peak < LIMIT_BYTES


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("", "the file has no commands"),
        ("; only a comment\n\n", "the file has no commands"),
        ("G1 F1800\nG90\n", "the file has no commands"),
        ("M104 S200\nG28\nM84\n", "only commands up to line 3"),
    ],
)
def test_empty_and_move_less_files_are_refused(tmp_path, proto_profile, text, fragment):
    """Regression: an empty file 'completed'; 0 moves was 'OK'."""
    path = tmp_path / "empty.gcode"
    path.write_text(text)
    with pytest.raises(GcodeError, match=f"no moves, nothing to print: {fragment}") as exc:
        preflight(path, proto_profile)
    assert exc.value.exit_code == 2


def test_cr_only_file_is_checked_line_by_line(tmp_path, proto_profile):
    """Regression: a CR-only file read as one line and passed with 0 moves."""
    body = START + "G1 X20 Y10 E2\nG1 X20 Y20 E3\n"
    lf, cr = tmp_path / "lf.gcode", tmp_path / "cr.gcode"
    lf.write_text(body)
    cr.write_bytes(body.replace("\n", "\r").encode())
    a, b = preflight(lf, proto_profile), preflight(cr, proto_profile)
    assert b.moves == a.moves == 4 and b.filament_mm == a.filament_mm
