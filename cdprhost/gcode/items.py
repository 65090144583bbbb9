"""What the reader yields: move chunks (numpy arrays) and small command records.

Every record carries ``line``, the 1-based source line, so later stages can name it.
Coordinates are in the G-code frame, millimetres, absolute (modes and offsets applied).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Literal, Union

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
    makes it jump), so ``e_end - e_start`` is the filament fed by each move.
    ``feedrate`` is mm/s. ``layer`` is -1 before the first layer.
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


@dataclass(frozen=True, slots=True)
class SetTemperature:
    """M104/M109 (hotend), M140/M190 (bed). ``wait_cooling``: the R form also waits when cooling."""

    line: int
    heater: Literal["hotend", "bed"]
    target_c: float
    wait: bool
    wait_cooling: bool = False


@dataclass(frozen=True, slots=True)
class Fan:
    """M106/M107: part-cooling fan ``index`` at ``speed`` in 0..1."""

    line: int
    speed: float
    index: int = 0


@dataclass(frozen=True, slots=True)
class Dwell:
    """G4: wait for the moves to finish, then pause ``seconds``."""

    line: int
    seconds: float


@dataclass(frozen=True, slots=True)
class Home:
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
class Message:
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
class Unknown:
    """A command the reader does not execute. ``harmless``: skipping it changes nothing printed."""

    line: int
    word: str
    harmless: bool


Command = Union[  # noqa: UP007 - a runtime alias used in isinstance checks
    SetTemperature,
    Fan,
    Dwell,
    Home,
    MotorsOff,
    WaitMoves,
    Message,
    ToolSelect,
    LayerChange,
    Unknown,
]
ProgramItem = Union[MoveChunk, Command]  # noqa: UP007
