"""Machine settings the reader needs to execute a few commands (pure values).

``FirmwareRetraction``: what G10/G11 do (M207/M208 and Klipper's SET_RETRACTION
change it while reading). ``ParkPoint``: where M600 parks the effector while the
operator changes the filament. Both in the G-code frame; the caller takes them
from the machine profile (``cdprhost.motion.program.reader_settings``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class FirmwareRetraction:
    """G10 pulls ``length_mm`` back at ``speed_mm_s``; G11 pushes ``length_mm + extra_mm``."""

    length_mm: float = 1.0
    speed_mm_s: float = 35.0
    extra_mm: float = 0.0
    unretract_speed_mm_s: float = 35.0


@dataclass(frozen=True, slots=True)
class ParkPoint:
    """M600: retract ``retract_mm``, lift ``lift_mm`` (up to ``z_max``), travel to ``xy``.

    ``xy`` and ``z_max`` in the G-code frame; ``speed_mm_s`` for the park travel.
    """

    xy: tuple[float, float]
    z_max: float
    lift_mm: float = 10.0
    retract_mm: float = 2.0
    speed_mm_s: float = 50.0
    retract_speed_mm_s: float = 25.0
