"""Every non-motion command the reader knows, and unknown ones."""

from __future__ import annotations

import pytest

from cdprhost.gcode import (
    ColdExtrusion,
    DisplayMessage,
    DwellCommand,
    Fan,
    FilamentChange,
    FlowFactor,
    GcodeError,
    HomeCommand,
    LayerChange,
    MotorsOff,
    MoveChunk,
    SetMotionLimits,
    SetTemperature,
    SpeedFactor,
    ToolSelect,
    UnknownCommand,
    WaitMoves,
)

from .helpers import commands, moves, read


@pytest.mark.parametrize(
    "line, expected",
    [
        ("M104 S210", SetTemperature(1, "hotend", 210.0, wait=False)),
        ("M109 S215", SetTemperature(1, "hotend", 215.0, wait=True)),
        ("M109 R180", SetTemperature(1, "hotend", 180.0, wait=True, wait_cooling=True)),
        ("M140 S60", SetTemperature(1, "bed", 60.0, wait=False)),
        ("M190 S65", SetTemperature(1, "bed", 65.0, wait=True)),
        ("M190 R40", SetTemperature(1, "bed", 40.0, wait=True, wait_cooling=True)),
        ("M104 T0 S200", SetTemperature(1, "hotend", 200.0, wait=False)),
        ("M106 S127.5", Fan(1, 0.5)),
        ("M106", Fan(1, 1.0)),
        ("M106 P1 S255", Fan(1, 1.0, index=1)),
        ("M106 S300", Fan(1, 1.0)),
        ("M107", Fan(1, 0.0)),
        ("G4 P250", DwellCommand(1, 0.25)),
        ("G4 S2", DwellCommand(1, 2.0)),
        ("G4", DwellCommand(1, 0.0)),
        ("G28", HomeCommand(1, ())),
        ("G28 X Y", HomeCommand(1, ("X", "Y"))),
        ("G28 Z0", HomeCommand(1, ("Z",))),
        ("M84", MotorsOff(1)),
        ("M18", MotorsOff(1)),
        ("M400", WaitMoves(1)),
        ("M117 Printing Layer 3; comment", DisplayMessage(1, "Printing Layer 3")),
        ("M117", DisplayMessage(1, "")),
        ("M117 X5 Y7", DisplayMessage(1, "X5 Y7")),
        ("m117 Mixed Case", DisplayMessage(1, "Mixed Case")),
        ("T0", ToolSelect(1, 0)),
        ("M73 P10 R5", UnknownCommand(1, "M73", harmless=True)),
        ("M204 S1000", SetMotionLimits(1, "M204", print_accel=1000.0, travel_accel=1000.0)),
        (
            "M204 P800 T1500 R900",
            SetMotionLimits(1, "M204", print_accel=800.0, travel_accel=1500.0, retract_accel=900.0),
        ),
        (
            "M201 X1000 Y900 Z200 E5000",
            SetMotionLimits(1, "M201", axis_accel=(1000.0, 900.0, 200.0, 5000.0)),
        ),
        (
            "M203 X200 Y200 Z12 E120",
            SetMotionLimits(1, "M203", axis_velocity=(200.0, 200.0, 12.0, 120.0)),
        ),
        ("M205 X8 Y10 Z0.4 E4.5", SetMotionLimits(1, "M205", corner_velocity=8.0)),
        ("M205 J0.02", SetMotionLimits(1, "M205", junction_deviation=0.02)),
        ('M862.3 P "MK3S" ; printer model check', UnknownCommand(1, "M862.3", harmless=True)),
        ("M115 U3.10.0", UnknownCommand(1, "M115", harmless=True)),
        ("M221 S100", FlowFactor(1, 1.0)),
        ("M221 S95", FlowFactor(1, 0.95)),
        ("M220 S50", SpeedFactor(1, 0.5)),
        ("M600", FilamentChange(1)),
        ("M302 P1", ColdExtrusion(1, True)),
        ("M302 S160", ColdExtrusion(1, None, 160.0)),
        ("M302", UnknownCommand(1, "M302", harmless=True)),
        ("M555 X10 Y10 W50 H50", UnknownCommand(1, "M555", harmless=True)),
        ("M569 S1 X Y", UnknownCommand(1, "M569", harmless=True)),
        ("M84 E", UnknownCommand(1, "M84", harmless=True)),
        ("G10 L2 P1 X0", UnknownCommand(1, "G10", harmless=False, text="G10 L2 P1 X0")),
        ("GET_POSITION", UnknownCommand(1, "GET_POSITION", harmless=True, text="GET_POSITION")),
        (
            "PRINT_START BED=60 EXTRUDER=215",
            UnknownCommand(
                1, "PRINT_START", harmless=False, text="PRINT_START BED=60 EXTRUDER=215"
            ),
        ),
        ("@pause", UnknownCommand(1, "@PAUSE", harmless=False, text="@PAUSE")),
        ("M84 S600", UnknownCommand(1, "M84", harmless=True)),
    ],
)
def test_single_command(line, expected):
    assert commands(read(line)) == [expected]


def test_commands_keep_file_order_and_split_chunks():
    items = read("G1 X1 F600\nG1 X2\nM106 S255\nG1 X3\nM107\nG1 X4\n")
    kinds = [type(i).__name__ for i in items]
    assert kinds == ["MoveChunk", "Fan", "MoveChunk", "Fan", "MoveChunk"]
    assert [len(i) for i in items if isinstance(i, MoveChunk)] == [2, 1, 1]
    assert items[1].line == 3 and items[3].line == 5


def test_home_returns_to_home_position_and_clears_offsets():
    items = read("G1 X10 Y10 Z10 F600\nG92 X0\nG28\nG1 X5\n", home_position=(1.0, 2.0, 3.0))
    m = moves(items)
    assert m["start"][0].tolist() == [1.0, 2.0, 3.0]
    assert m["end"][0].tolist() == [10.0, 10.0, 10.0]
    assert m["start"][1].tolist() == [1.0, 2.0, 3.0]  # after G28
    assert m["end"][1].tolist() == [5.0, 2.0, 3.0]  # G92 X0 offset cleared by G28
    assert any(isinstance(i, HomeCommand) for i in items)


@pytest.mark.parametrize(
    "line, column, fragment",
    [
        ("T1", 1, "single extruder"),
        ("M104 T2 S200", 6, "single extruder"),
        ("M104 S-5", 6, "below 0"),
        ("G4 P-10", 4, "below 0"),
        ("M106 S-1", 6, "below 0"),
        ("S10 Y5", 1, "no command before 'S10'"),
    ],
)
def test_bad_command_values(line, column, fragment):
    with pytest.raises(GcodeError) as exc:
        read("G1 X1 F100\n" + line)
    assert exc.value.line == 2 and exc.value.column == column
    assert fragment in str(exc.value)
    assert str(exc.value).startswith(f"<lines>:2:{column}: ")


def test_annotations_prusa_style():
    text = (
        "G1 Z5 F600\n;LAYER_CHANGE\n;Z:0.2\n;HEIGHT:0.2\nG1 X1 E1\n;TYPE:Perimeter\n"
        ";LAYER_CHANGE\n;Z:0.4\nG1 Z0.4\nG1 X2 E2\n"
    )
    items = read(text)
    layers = [i for i in items if isinstance(i, LayerChange)]
    assert layers == [LayerChange(2, 0, 0.2), LayerChange(7, 1, 0.4)]
    m = moves(items)
    assert m["layer"].tolist() == [-1, 0, 1, 1]
    # each LayerChange comes right before the moves of its layer
    kinds = [type(i).__name__ for i in items]
    assert kinds == ["MoveChunk", "LayerChange", "MoveChunk", "LayerChange", "MoveChunk"]


def test_annotations_cura_style():
    text = ";LAYER_COUNT:2\n;LAYER:0\nG1 X1 Y1 Z0.2 E1 F600\n;TYPE:WALL-OUTER\n;LAYER:1\nG1 Z0.4\nG1 X2 E2\n"
    items = read(text)
    assert [i for i in items if isinstance(i, LayerChange)] == [
        LayerChange(2, 0, None),
        LayerChange(5, 1, None),
    ]
    assert moves(items)["layer"].tolist() == [0, 1, 1]


def test_layers_from_height_without_annotations():
    text = "G1 Z5 F600\nG1 Z0.2\nG1 X1 E1\nG1 X2 E2\nG1 Z0.4\nG1 X1 E3\nG1 Z2\nG1 X5\nG1 Z0.4\nG1 X0 E4\n"
    items = read(text)
    layers = [i for i in items if isinstance(i, LayerChange)]
    assert [(lc.line, lc.index, lc.z) for lc in layers] == [(3, 0, 0.2), (6, 1, 0.4)]
    assert moves(items)["layer"].tolist() == [-1, -1, 0, 0, 0, 1, 1, 1, 1, 1]
