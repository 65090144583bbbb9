"""Streaming G-code reader: sliced G-code -> absolute move chunks and command records.

Entry point: `read_program`. See the README section "G-code" for the dialect.
"""

from cdprhost.gcode.errors import GcodeError
from cdprhost.gcode.items import (
    CancelObject,
    ColdExtrusion,
    Command,
    DisplayMessage,
    DwellCommand,
    Fan,
    FilamentChange,
    FlowFactor,
    HomeCommand,
    IgnoredParameters,
    LayerChange,
    MotorsOff,
    MoveChunk,
    MoveKind,
    ObjectDefine,
    ObjectEnd,
    ObjectStart,
    PidAutotune,
    ProgramItem,
    SetMotionLimits,
    SetTemperature,
    SpeedFactor,
    ToolSelect,
    UnknownCommand,
    WaitMoves,
)
from cdprhost.gcode.reader import read_program
from cdprhost.gcode.settings import FirmwareRetraction, ParkPoint
from cdprhost.gcode.summary import ProgramSummary

__all__ = [
    "CancelObject",
    "ColdExtrusion",
    "Command",
    "DisplayMessage",
    "DwellCommand",
    "Fan",
    "FilamentChange",
    "FirmwareRetraction",
    "FlowFactor",
    "GcodeError",
    "HomeCommand",
    "IgnoredParameters",
    "LayerChange",
    "MotorsOff",
    "MoveChunk",
    "MoveKind",
    "ObjectDefine",
    "ObjectEnd",
    "ObjectStart",
    "ParkPoint",
    "PidAutotune",
    "ProgramItem",
    "ProgramSummary",
    "SetMotionLimits",
    "SetTemperature",
    "SpeedFactor",
    "ToolSelect",
    "UnknownCommand",
    "WaitMoves",
    "read_program",
]
