"""The G-code slicers emit: line ends, continuation lines, extended commands, factors,
firmware retraction, the filament change, objects, ignored parameters, exponents."""

from __future__ import annotations

import numpy as np
import pytest

from cdprhost.gcode import (
    CancelObject,
    FilamentChange,
    FlowFactor,
    GcodeError,
    IgnoredParameters,
    LayerChange,
    MoveKind,
    ObjectDefine,
    ObjectEnd,
    ObjectStart,
    ParkPoint,
    ProgramSummary,
    SetTemperature,
    SpeedFactor,
    UnknownCommand,
    read_program,
)
from cdprhost.gcode.objects import exclude_objects, object_names
from cdprhost.gcode.settings import FirmwareRetraction

from .helpers import commands, moves, read

TEXT = "G1 X1 Y1 E1 F600\nG1 X2 E2\nG1 X3 E3\n"


@pytest.mark.parametrize("sep", ["\n", "\r\n", "\r"], ids=["lf", "crlf", "cr"])
def test_every_line_end_reads_the_same(tmp_path, sep):
    path = tmp_path / "part.gcode"
    path.write_bytes(TEXT.replace("\n", sep).encode())
    m = moves(list(read_program(path, block_bytes=7)))
    assert m["line"].tolist() == [1, 2, 3]
    assert m["end"][:, 0].tolist() == [1.0, 2.0, 3.0]


def test_cr_only_file_has_its_lines():
    """Regression: a CR-only file read as one line (0 moves, 'OK')."""
    s = ProgramSummary.of(read_program([TEXT.replace("\n", "\r").encode()]))
    assert s.moves == 3 and s.last_line == 3


def test_continuation_lines_repeat_the_motion_command():
    m = moves(read("G1 X1 Y1 F600\nX2 Y2\nF1200\nX3\nG0 X4\nY5\n"))
    assert m["end"][:, :2].tolist() == [[1, 1], [2, 2], [3, 2], [4, 2], [4, 5]]
    assert m["feedrate"].tolist() == [10, 10, 20, 20, 20]
    assert m["rapid"].tolist() == [False, False, False, True, True]


def test_continuation_across_blocks_and_arcs():
    m = moves(read("G2 X2 Y0 I1 J0 F600\nX4 Y0 I1 J0\n", block_lines=1))
    assert m["end"][-1, :2].tolist() == [4.0, 0.0]
    assert len(set(m["line"].tolist())) == 2 and len(m["line"]) > 4


def test_bare_feedrate_before_any_motion_is_fine():
    m = moves(read("F1800\nG1 X1\n"))
    assert m["feedrate"].tolist() == [30.0]


def test_continuation_without_a_motion_command_is_an_error():
    with pytest.raises(GcodeError, match=r"<lines>:2:1: 'X2' continues no motion command"):
        read("M104 S0\nX2 Y1\n")


def test_ignored_parameters_are_reported_not_refused():
    items = read("G0 X1 S0 F600\nG1 X2 A5\nG92 X0 F100\nG1 X3 Y0 I1\n")
    got = [c for c in commands(items) if isinstance(c, IgnoredParameters)]
    assert got == [
        IgnoredParameters(1, "G0", "S0"),
        IgnoredParameters(2, "G1", "A5"),
        IgnoredParameters(3, "G92", "F100"),
        IgnoredParameters(4, "G1", "I1"),
    ]
    assert moves(items)["end"][:, 0].tolist() == [1.0, 2.0, 5.0]  # G92 X0 at X2


def test_reprapfirmware_tool_temperatures_and_m116():
    """RepRapFirmware files heat with `G10 P0 S<active> R<standby>` and wait with M116:
    read as firmware retraction or skipped, the print started cold."""
    items = read("G10 P0 S210 R170\nM140 S60\nM116\nG10 P0 R150\nG10 P1 S200\nG10\n")
    temps = [c for c in commands(items) if isinstance(c, SetTemperature)]
    assert temps == [
        SetTemperature(1, "hotend", 210.0, False),
        SetTemperature(2, "bed", 60.0, False),
        SetTemperature(3, "hotend", 210.0, True),
        SetTemperature(3, "bed", 60.0, True),
    ]
    unknown = [c for c in commands(items) if isinstance(c, UnknownCommand)]
    assert [u.line for u in unknown] == [5]  # another tool's temperature: a warning
    assert moves(items)["line"].tolist() == [6]  # the bare G10 still retracts


def test_m207_z_hop_is_a_warning_not_silence():
    items = read("M207 S2 F2400 Z0.4\nM207 S1 Z0\nG1 X1\n")
    got = [c for c in commands(items) if isinstance(c, IgnoredParameters)]
    assert got == [IgnoredParameters(1, "M207", "Z0.4")]  # Z0 asks for no hop: nothing to say


@pytest.mark.parametrize("number", ["1e308", "1E5", "2.5e-3", "1e+2", ".5e3"])
def test_numbers_with_an_exponent_are_refused(number):
    """Regression: 'G1 X1e308' read as X1 E308."""
    with pytest.raises(GcodeError, match="number with an exponent"):
        read(f"G1 X{number} F600\n")


def test_compact_lines_keep_their_e():
    m = moves(read("G1X10Y5E0.5F600\n"))
    assert m["end"][0].tolist() == [10.0, 5.0, 0.0] and m["e_end"][0] == 0.5


def test_extended_commands_are_unknown_not_malformed():
    text = (
        "PRINT_START BED=60 EXTRUDER=215\nSET_PRESSURE_ADVANCE ADVANCE=0.04\n"
        "G1 X1 E1 F600\nget_position\nBED_MESH_CALIBRATE\nPRINT_END\n"
    )
    cmds = [c for c in commands(read(text)) if isinstance(c, UnknownCommand)]
    assert [(c.line, c.word, c.harmless) for c in cmds] == [
        (1, "PRINT_START", False),
        (2, "SET_PRESSURE_ADVANCE", True),
        (4, "GET_POSITION", True),
        (5, "BED_MESH_CALIBRATE", True),
        (6, "PRINT_END", False),
    ]
    assert cmds[0] == UnknownCommand(1, "PRINT_START", False, "PRINT_START BED=60 EXTRUDER=215")


def test_speed_and_flow_factors_apply_to_the_moves_after_them():
    items = read("M83\nG1 X1 E1 F600\nM220 S50\nM221 S90\nG1 X2 E1\nM221 S100\nG1 X3 E1\n")
    m = moves(items)
    np.testing.assert_allclose(m["feedrate"], [10, 5, 5])
    np.testing.assert_allclose(m["e_end"] - m["e_start"], [1, 0.9, 1])
    assert [c for c in commands(items) if isinstance(c, (SpeedFactor, FlowFactor))] == [
        SpeedFactor(3, 0.5),
        FlowFactor(4, 0.9),
        FlowFactor(6, 1.0),
    ]
    s = ProgramSummary.of(items)
    assert s.filament_mm == pytest.approx(3.0) and s.filament_fed_mm == pytest.approx(2.9)


def test_flow_factor_with_absolute_e_keeps_the_axis_continuous():
    m = moves(read("G1 X1 E1 F600\nM221 S50\nG1 X2 E3\nG92 E0\nG1 X3 E2\n"))
    np.testing.assert_allclose(m["e_start"][1:], m["e_end"][:-1])
    np.testing.assert_allclose(m["e_end"] - m["e_start"], [1, 1, 1])


def test_firmware_retraction_uses_the_settings_and_m207():
    r = FirmwareRetraction(length_mm=0.8, speed_mm_s=40, extra_mm=0.1, unretract_speed_mm_s=20)
    items = read(
        "G1 X1 E1 F600\nG10\nG10\nG1 X5 F6000\nG11\nG1 X6 E2\nM207 S2 F1800\nG10\nG11\n",
        retraction=r,
    )
    m = moves(items)
    kinds = [MoveKind(k).name for k in m["kind"]]
    assert kinds == [
        "EXTRUDE",
        "RETRACT",
        "TRAVEL",
        "UNRETRACT",
        "EXTRUDE",
        "RETRACT",
        "UNRETRACT",
    ]
    de = m["e_end"] - m["e_start"]
    np.testing.assert_allclose(de, [1, -0.8, 0, 0.9, 1, -2, 2.1])
    np.testing.assert_allclose(m["feedrate"][[1, 3, 5]], [40, 20, 30])
    np.testing.assert_allclose(m["e_start"][1:], m["e_end"][:-1])  # continuous machine E


def test_filament_change_parks_and_comes_back():
    park = ParkPoint(xy=(0.0, -40.0), z_max=50.0, lift_mm=10.0, retract_mm=2.0, speed_mm_s=50.0)
    items = [
        i
        for i in read("G1 X10 Y10 Z45 E1 F600\nM600\nG1 X11 E2\n", park=park)
        if not isinstance(i, LayerChange)
    ]
    kinds = [type(i).__name__ for i in items]
    assert kinds == ["MoveChunk", "MoveChunk", "FilamentChange", "MoveChunk", "MoveChunk"]
    go, back = items[1], items[3]
    assert go.end[-1].tolist() == [0.0, -40.0, 50.0]  # lift capped at z_max
    assert back.end[-1].tolist() == [10.0, 10.0, 45.0]
    assert (go.e_end[-1] - go.e_start[0], back.e_end[-1] - back.e_start[0]) == (-2.0, 2.0)
    assert items[4].start[0].tolist() == [10.0, 10.0, 45.0]


def test_filament_change_without_park_settings_only_waits():
    assert commands(read("G1 X1 F600\nM600\n")) == [FilamentChange(2)]


def test_m486_and_exclude_object_labels():
    text = (
        'M486 T2\nM486 S0 A"cube"\nG1 X1 E1 F600\nM486 S1\nG1 X5 E2\nM486 S-1\n'
        "EXCLUDE_OBJECT_DEFINE NAME=part_a CENTER=10,20\nEXCLUDE_OBJECT_START NAME=part_a\n"
        "G1 X6 E3\nEXCLUDE_OBJECT_END NAME=part_a\nEXCLUDE_OBJECT NAME=part_a\nM486 P1\n"
    )
    cmds = [c for c in commands(read(text)) if not isinstance(c, (UnknownCommand, LayerChange))]
    assert cmds == [
        ObjectDefine(2, "0", None, "cube"),
        ObjectStart(2, "0"),
        ObjectEnd(4, "0"),
        ObjectDefine(4, "1", None, ""),
        ObjectStart(4, "1"),
        ObjectEnd(6, "1"),
        ObjectDefine(7, "PART_A", (10.0, 20.0), ""),
        ObjectStart(8, "PART_A"),
        ObjectEnd(10, "PART_A"),
        CancelObject(11, "PART_A"),
        CancelObject(12, "1"),
    ]
    assert object_names(read(text)) == ["0", "1", "PART_A"]


def test_cancelled_objects_are_skipped_with_a_travel_and_continuous_e():
    text = (
        "M83\nG1 X0 Y0 F6000\nM486 S0\nG1 X10 E1 F600\nM486 S1\nG0 X20 F6000\nG1 X30 E1 F600\n"
        "M486 S2\nG0 X40 Y5\nG1 X50 E1 F600\nM486 S-1\n"
    )
    kept = list(exclude_objects(read_program(text.splitlines()), ["1"]))
    m = moves(kept)
    # object 1 (lines 6-7) is gone; the machine travels from X10 to object 2's first point
    assert 6 not in m["line"].tolist() and 7 not in m["line"].tolist()
    np.testing.assert_allclose(m["e_start"][1:], m["e_end"][:-1])
    assert m["e_end"][-1] == pytest.approx(2.0)
    np.testing.assert_allclose(m["start"][1:], m["end"][:-1])


def test_bad_bytes_are_shown_as_escapes_not_surrogates():
    with pytest.raises(GcodeError) as exc:
        list(read_program([b"G1 X1 F600", b"G1 Y\xc2\xff"]))
    assert "\\udc" not in str(exc.value) and "\\xc2" in str(exc.value)


def test_item_names_do_not_clash_with_the_wire_protocol():
    import cdprhost.gcode.items as items
    import firmware_protocol.messages as messages

    def own(module):
        return {
            n for n, v in vars(module).items() if getattr(v, "__module__", "") == module.__name__
        }

    gcode_names, wire_names = own(items), own(messages)
    assert gcode_names & wire_names == set()
    assert {"HomeCommand", "DwellCommand", "DisplayMessage", "UnknownCommand"} <= gcode_names


KLIPPER_TEST_STYLE = """\
DICTIONARY atmega2560.dict
CONFIG example.cfg

# Start by homing the printer.
G28
G90
G1 F6000
GET_POSITION
SET_GCODE_OFFSET Z=.1
M206 Z-.2
SET_VELOCITY_LIMIT ACCEL=100 VELOCITY=20 SQUARE_CORNER_VELOCITY=1 ACCEL_TO_DECEL=200
SET_PRESSURE_ADVANCE EXTRUDER=extruder ADVANCE=.001
M486 T3
M486 S0
  G0 X10
M486 S-1
M486 S1
  G1 X11 E0.5
M486 C
M486 U1
EXCLUDE_OBJECT
G1 X0 Y0 E.01
"""


def test_klipper_test_files_read_with_warnings_not_errors():
    items = read(KLIPPER_TEST_STYLE)
    unknown = [(c.word, c.harmless) for c in commands(items) if isinstance(c, UnknownCommand)]
    assert unknown == [
        ("DICTIONARY", False),
        ("CONFIG", False),
        ("GET_POSITION", True),
        ("SET_GCODE_OFFSET", False),
        ("M206", False),
        ("SET_PRESSURE_ADVANCE", True),
        ("M486 U", False),
    ]
    assert moves(items)["line"].tolist() == [15, 18, 22]
    assert CancelObject(19, "1") in commands(items)
