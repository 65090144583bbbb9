"""Modal state carried from line to line (and block to block) while reading."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdprhost.gcode.annotations import LayerStyle
from cdprhost.gcode.items import LayerChange

DEFAULT_FEEDRATE_MM_S = 25.0  # Marlin's start-up feedrate (1500 mm/min)


@dataclass
class ModalState:
    """Position (G-code frame, mm, continuous machine E), G92 offsets and modes.

    ``pos`` is X, Y, Z, E; the programmed coordinate of an axis is ``pos - off``.
    Relative E holds while G91 or M83 is in force (Klipper's rule: G90 does not undo M83).
    """

    home: np.ndarray
    pos: np.ndarray = field(init=False)
    off: np.ndarray = field(default_factory=lambda: np.zeros(4))
    relative: bool = False  # G91
    relative_e: bool = False  # M83
    scale: float = 1.0  # 25.4 under G20
    feed: float = DEFAULT_FEEDRATE_MM_S
    plane: int = 17
    layer: int = -1
    layer_style: LayerStyle | None = None
    z_top: float = -np.inf  # highest extruding Z so far (height-detected layers)
    next_n: int | None = None
    pending_layer: LayerChange | None = None

    def __post_init__(self) -> None:
        self.home = np.asarray(self.home, dtype=np.float64).reshape(3)
        self.pos = np.concatenate([self.home, [0.0]])

    @property
    def abs_xyz(self) -> bool:
        return not self.relative

    @property
    def abs_e(self) -> bool:
        return not (self.relative or self.relative_e)
