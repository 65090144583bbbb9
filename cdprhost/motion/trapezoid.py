"""Planned moves: trapezoidal speed profiles, their phases and timing.

Each move accelerates at ``accel`` from ``v_start`` to ``v_cruise``, cruises, and
decelerates to ``v_end``. Speeds are along the move's path: the effector's path,
or the filament for extrude-only moves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprhost.motion.moves import MoveBlock

Arr = np.ndarray | float


@dataclass(frozen=True)
class PlannedMoves:
    moves: MoveBlock
    length: np.ndarray  # (n,) mm along the path
    kinematic: np.ndarray  # (n,) bool
    accel: np.ndarray  # (n,) mm/s^2
    v_start: np.ndarray  # (n,) mm/s
    v_cruise: np.ndarray
    v_end: np.ndarray
    t_start: np.ndarray  # (n,) s since the program started
    chord_step: np.ndarray  # (n,) longest piece within the chord tolerance (mm)
    module_limited: np.ndarray  # (n,) bool: module limits slowed it below its feedrate

    def __len__(self) -> int:
        return int(self.length.shape[0])

    @property
    def accel_distance(self) -> np.ndarray:
        return np.clip((self.v_cruise**2 - self.v_start**2) / (2.0 * self.accel), 0.0, self.length)

    @property
    def decel_distance(self) -> np.ndarray:
        return np.clip(
            (self.v_cruise**2 - self.v_end**2) / (2.0 * self.accel),
            0.0,
            self.length - self.accel_distance,
        )

    @property
    def duration(self) -> np.ndarray:
        return move_durations(self.length, self.accel, self.v_start, self.v_cruise, self.v_end)

    @property
    def t_end(self) -> float:
        """End time of the last move (s)."""
        if not len(self):
            return 0.0
        return float(self.t_start[-1] + self.duration[-1])

    def take(self, index: Any) -> PlannedMoves:
        return PlannedMoves(self.moves.take(index), *(getattr(self, f)[index] for f in _ARRAYS))

    def time_at(self, move: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Time since the move's start and speed at path position ``x`` of ``move`` (arrays)."""
        return time_at(
            x,
            self.length[move],
            self.accel[move],
            self.v_start[move],
            self.v_cruise[move],
            self.v_end[move],
        )


_ARRAYS = (
    "length",
    "kinematic",
    "accel",
    "v_start",
    "v_cruise",
    "v_end",
    "t_start",
    "chord_step",
    "module_limited",
)


def move_durations(length: Arr, accel: Arr, v_start: Arr, v_cruise: Arr, v_end: Arr) -> np.ndarray:
    d_acc = np.clip((v_cruise**2 - v_start**2) / (2.0 * accel), 0.0, length)
    d_dec = np.clip((v_cruise**2 - v_end**2) / (2.0 * accel), 0.0, length - d_acc)
    cruise = np.maximum(length - d_acc - d_dec, 0.0)
    return (
        (v_cruise - v_start) / accel
        + cruise / np.maximum(v_cruise, 1e-300)
        + (v_cruise - v_end) / accel
    )


def time_at(
    x: Arr,
    length: Arr,
    accel: Arr,
    v_start: Arr,
    v_cruise: Arr,
    v_end: Arr,
) -> tuple[np.ndarray, np.ndarray]:
    """(t, v) at path position x (0 <= x <= length) of a trapezoid, vectorised."""
    d_acc = np.clip((v_cruise**2 - v_start**2) / (2.0 * accel), 0.0, length)
    d_dec = np.clip((v_cruise**2 - v_end**2) / (2.0 * accel), 0.0, length - d_acc)
    x2 = length - d_dec
    t_acc = (v_cruise - v_start) / accel
    total = t_acc + np.maximum(x2 - d_acc, 0.0) / v_cruise + (v_cruise - v_end) / accel
    v_a = np.sqrt(v_start**2 + 2.0 * accel * np.minimum(x, d_acc))
    v_d = np.sqrt(v_end**2 + 2.0 * accel * np.maximum(length - x, 0.0))
    in_acc = x <= d_acc
    in_dec = x >= x2
    t = np.where(
        in_acc,
        (v_a - v_start) / accel,
        np.where(
            in_dec,
            total - (np.minimum(v_d, v_cruise) - v_end) / accel,
            t_acc + (x - d_acc) / v_cruise,
        ),
    )
    v = np.where(in_acc, v_a, np.where(in_dec, np.minimum(v_d, v_cruise), v_cruise))
    return t, v
