"""Modal state carried from line to line (and block to block) while reading."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from cdprhost.gcode.annotations import LayerStyle
from cdprhost.gcode.items import LayerChange
from cdprhost.gcode.settings import FirmwareRetraction, ParkPoint

DEFAULT_FEEDRATE_MM_S = 25.0  # Marlin's start-up feedrate (1500 mm/min)


@dataclass
class ModalState:
    """Position (G-code frame, mm), G92 offsets and modes.

    ``pos`` is X, Y, Z, E; the programmed coordinate of an axis is ``pos - off``.
    ``placement`` is added to the X/Y offsets at the start and after every G28 (it
    shifts the whole program). ``e_machine`` is the continuous machine E axis: it
    follows ``pos[3]`` scaled by the flow factor, and firmware retraction moves it
    alone. Relative E holds while G91 or M83 is in force (Klipper's rule: G90 does
    not undo M83).
    """

    home: np.ndarray
    placement: np.ndarray = field(default_factory=lambda: np.zeros(2))
    retraction: FirmwareRetraction = field(default_factory=FirmwareRetraction)
    park: ParkPoint | None = None
    pos: np.ndarray = field(init=False)
    off: np.ndarray = field(init=False)
    e_machine: float = 0.0
    relative: bool = False  # G91
    relative_e: bool = False  # M83
    scale: float = 1.0  # 25.4 under G20
    feed: float = DEFAULT_FEEDRATE_MM_S
    speed_factor: float = 1.0  # M220
    speed_factor_saved: float = 1.0  # M220 B / R
    flow_factor: float = 1.0  # M221
    filament_diameter_mm: float = 1.75
    volumetric_scale: float = 1.0  # E in mm^3 (M200 D, UltiGCode): 1 / filament area
    retracted: bool = False  # after G10, until G11
    motion_mode: int | None = None  # last G0-G3, for lines that continue it
    plane: int = 17
    layer: int = -1
    layer_style: LayerStyle | None = None
    z_top: float = -np.inf  # highest extruding Z so far (height-detected layers)
    next_n: int | None = None
    pending_layer: LayerChange | None = None
    mute: tuple[tuple[int, int], ...] = ()  # line ranges whose machine settings do not count
    objects: dict[int, str] = field(default_factory=dict)  # M486 id -> name
    object_id: int | None = None  # M486 S: the object being printed
    targets: dict[Literal["hotend", "bed"], float] = field(default_factory=dict)  # for M116

    def __post_init__(self) -> None:
        self.home = np.asarray(self.home, dtype=np.float64).reshape(3)
        self.placement = np.asarray(self.placement, dtype=np.float64).reshape(2)
        self.pos = np.concatenate([self.home, [0.0]])
        self.off = self.home_offsets()

    def home_offsets(self) -> np.ndarray:
        """X, Y, Z, E offsets at the start and after G28: the placement shift."""
        return np.array([self.placement[0], self.placement[1], 0.0, 0.0])

    def muted(self, line: int) -> bool:
        return any(a <= line <= b for a, b in self.mute)

    @property
    def e_factor(self) -> float:
        """Machine E per programmed E: the flow factor, and the volumetric conversion."""
        return self.flow_factor * self.volumetric_scale

    @property
    def abs_xyz(self) -> bool:
        return not self.relative

    @property
    def abs_e(self) -> bool:
        return not (self.relative or self.relative_e)
