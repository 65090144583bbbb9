"""Streaming G-code reader: sliced G-code -> absolute move chunks and command records.

Entry point: `read_program`. See the README section "G-code" for the dialect.
"""

from cdprhost.gcode.errors import GcodeError
from cdprhost.gcode.items import (
    Command,
    Dwell,
    Fan,
    Home,
    LayerChange,
    Message,
    MotorsOff,
    MoveChunk,
    MoveKind,
    ProgramItem,
    SetTemperature,
    ToolSelect,
    Unknown,
    WaitMoves,
)
from cdprhost.gcode.reader import read_program
from cdprhost.gcode.summary import ProgramSummary

__all__ = [
    "Command",
    "Dwell",
    "Fan",
    "GcodeError",
    "Home",
    "LayerChange",
    "Message",
    "MotorsOff",
    "MoveChunk",
    "MoveKind",
    "ProgramItem",
    "ProgramSummary",
    "SetTemperature",
    "ToolSelect",
    "Unknown",
    "WaitMoves",
    "read_program",
]
