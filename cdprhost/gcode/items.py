"""What the reader yields: move chunks (numpy arrays) and small command records.

Every record carries ``line``, the 1-based source line, so later stages can name it.
Coordinates are in the G-code frame, millimetres, absolute (modes and offsets applied).

The stream is a closed union (`ProgramItem`): consumers dispatch with ``match`` and
end with a ``case _`` only where "every other item" is meant. The names do not
clash with the wire protocol's messages (``firmware_protocol.messages``): the
G-code side says *Command* (``HomeCommand``, ``DwellCommand``), the protocol does not.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

import numpy as np


class MoveKind(IntEnum):
    """Classification of one linear move (values stored in ``MoveChunk.kind``)."""

    TRAVEL = 0  # XY (maybe Z) motion, extruder still
    EXTRUDE = 1  # motion while extruding
    RETRACT = 2  # extruder only, backwards
    UNRETRACT = 3  # extruder only, forwards (prime)
    Z_ONLY = 4  # pure Z motion, extruder still (layer change, lift)
    WIPE = 5  # motion while retracting


@dataclass(frozen=True, eq=False)
class MoveChunk:
    """A run of consecutive linear moves (G0/G1, segmented G2/G3), read-only arrays.

    ``e_start``/``e_end`` are positions on a continuous machine E axis (G92 E never
    makes it jump), so ``e_end - e_start`` is the filament fed by each move (after
    the flow factor of M221). ``feedrate`` is mm/s (after the speed factor of M220).
    ``layer`` is -1 before the first layer.
    """

    start: np.ndarray  # (n, 3) float64
    end: np.ndarray  # (n, 3) float64
    e_start: np.ndarray  # (n,) float64
    e_end: np.ndarray  # (n,) float64
    feedrate: np.ndarray  # (n,) float64, mm/s
    line: np.ndarray  # (n,) int64
    layer: np.ndarray  # (n,) int32
    kind: np.ndarray  # (n,) uint8, MoveKind values
    rapid: np.ndarray  # (n,) bool, True for G0

    def __len__(self) -> int:
        return int(self.line.shape[0])

    @property
    def de(self) -> np.ndarray:
        """Filament fed by each move (mm, negative when retracting)."""
        return self.e_end - self.e_start

    @property
    def length(self) -> np.ndarray:
        """Cartesian length of each move (mm)."""
        return np.sqrt(((self.end - self.start) ** 2).sum(axis=1))

    def take(self, index: slice | np.ndarray) -> MoveChunk:
        """Rows selected by a slice, a boolean mask or an index array."""
        return MoveChunk(*(getattr(self, f)[index] for f in CHUNK_FIELDS))


CHUNK_FIELDS = ("start", "end", "e_start", "e_end", "feedrate", "line", "layer", "kind", "rapid")


@dataclass(frozen=True, slots=True)
class SetTemperature:
    """M104/M109 (hotend), M140/M190 (bed). ``wait_cooling``: the R form also waits when cooling."""

    line: int
    heater: Literal["hotend", "bed"]
    target_c: float
    wait: bool
    wait_cooling: bool = False


@dataclass(frozen=True, slots=True)
class PidAutotune:
    """M303 E<0 hotend | -1 bed> S<target> C<cycles>: the device's relay autotune (it
    reports the gains; the heater is off afterwards)."""

    line: int
    heater: Literal["hotend", "bed"]
    target_c: float
    cycles: int = 5


@dataclass(frozen=True, slots=True)
class Fan:
    """M106/M107: part-cooling fan ``index`` at ``speed`` in 0..1."""

    line: int
    speed: float
    index: int = 0


@dataclass(frozen=True, slots=True)
class DwellCommand:
    """G4: wait for the moves to finish, then pause ``seconds``."""

    line: int
    seconds: float


@dataclass(frozen=True, slots=True)
class HomeCommand:
    """G28. ``axes`` as written (empty: all). On the cable robot every G28 homes the whole machine."""

    line: int
    axes: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class MotorsOff:
    """M84/M18 (without S): release the motors."""

    line: int


@dataclass(frozen=True, slots=True)
class WaitMoves:
    """M400: wait until all queued moves have finished."""

    line: int


@dataclass(frozen=True, slots=True)
class DisplayMessage:
    """M117: text for the display."""

    line: int
    text: str


@dataclass(frozen=True, slots=True)
class ToolSelect:
    """T0 (the only tool: the machine has one extruder)."""

    line: int
    tool: int = 0


@dataclass(frozen=True, slots=True)
class LayerChange:
    """Start of layer ``index`` (0-based); ``z`` from a ``;Z:`` annotation or the detected height."""

    line: int
    index: int
    z: float | None = None


@dataclass(frozen=True, slots=True)
class SpeedFactor:
    """M220 S: the reader already applies ``factor`` to the feedrates that follow."""

    line: int
    factor: float


@dataclass(frozen=True, slots=True)
class FlowFactor:
    """M221 S: the reader already applies ``factor`` to the extrusion that follows."""

    line: int
    factor: float


@dataclass(frozen=True, slots=True)
class SetMotionLimits:
    """Limits the file asks for (M201, M203, M204, M205, Klipper SET_VELOCITY_LIMIT).

    None: unchanged. Per axis X, Y, Z, E. The planner clamps every value to the
    profile's own limits (a file can slow the machine down, never speed it up).
    """

    line: int
    word: str
    axis_accel: tuple[float | None, float | None, float | None, float | None] = (
        None,
        None,
        None,
        None,
    )
    axis_velocity: tuple[float | None, float | None, float | None, float | None] = (
        None,
        None,
        None,
        None,
    )
    print_accel: float | None = None  # M204 P (or S): moves that extrude
    travel_accel: float | None = None  # M204 T (or S): moves that do not
    retract_accel: float | None = None  # M204 R: extruder-only moves
    velocity: float | None = None  # SET_VELOCITY_LIMIT VELOCITY
    corner_velocity: float | None = None  # M205 X/Y (jerk) or SQUARE_CORNER_VELOCITY, mm/s
    junction_deviation: float | None = None  # M205 J, mm


@dataclass(frozen=True, slots=True)
class ColdExtrusion:
    """M302: ``allow`` (P1 / bare M302: True, P0: False) and/or the minimum temperature (S)."""

    line: int
    allow: bool | None
    min_temp_c: float | None = None


@dataclass(frozen=True, slots=True)
class FilamentChange:
    """M600: the machine is parked (the reader put the park moves around this record) and
    waits for the operator to change the filament; the print goes on when they resume."""

    line: int


@dataclass(frozen=True, slots=True)
class ObjectDefine:
    """An object of the plate (Klipper EXCLUDE_OBJECT_DEFINE; M486 S<id>, A<label>).

    ``name`` identifies it (the M486 id as text); ``label`` is a human name, if any;
    ``center`` in the G-code frame (placement applied), if the file gives one.
    """

    line: int
    name: str
    center: tuple[float, float] | None = None
    label: str = ""


@dataclass(frozen=True, slots=True)
class ObjectStart:
    """The moves that follow belong to object ``name`` (EXCLUDE_OBJECT_START, M486 S<id>)."""

    line: int
    name: str


@dataclass(frozen=True, slots=True)
class ObjectEnd:
    """The moves of object ``name`` end here (EXCLUDE_OBJECT_END, M486 S-1)."""

    line: int
    name: str


@dataclass(frozen=True, slots=True)
class CancelObject:
    """The file itself cancels object ``name`` (EXCLUDE_OBJECT NAME=..., M486 P<id>)."""

    line: int
    name: str


@dataclass(frozen=True, slots=True)
class IgnoredParameters:
    """Parameters a printer ignores on a known command (``S`` on ``G0``): a warning, no effect."""

    line: int
    word: str
    letters: str


@dataclass(frozen=True, slots=True)
class UnknownCommand:
    """A command the reader does not execute.

    ``harmless``: a command known to change nothing printed here (reports, progress,
    bed levelling...): noted. Otherwise unknown: a warning when checking, skipped when
    printing (``--strict``: an error). ``text``: the line as written, for extended
    (Klipper) commands.
    """

    line: int
    word: str
    harmless: bool
    text: str = ""


Command = (
    SetTemperature
    | PidAutotune
    | Fan
    | DwellCommand
    | HomeCommand
    | MotorsOff
    | WaitMoves
    | DisplayMessage
    | ToolSelect
    | LayerChange
    | SpeedFactor
    | FlowFactor
    | SetMotionLimits
    | ColdExtrusion
    | FilamentChange
    | ObjectDefine
    | ObjectStart
    | ObjectEnd
    | CancelObject
    | IgnoredParameters
    | UnknownCommand
)
ProgramItem = MoveChunk | Command
