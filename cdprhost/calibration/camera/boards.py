"""ChArUco boards: what is printed, and where it sits (camera-session.md, "Board frame").

A board's frame is OpenCV's (4.7+): ``getChessboardCorners()`` gives the inner corners
(z = 0 on the printed face, z = x cross y points into the board). Marker ids run from
``first_marker_id`` in OpenCV's order. Placement: ``p_base = origin + R p_board`` with
``R = Rz(c) Ry(b) Rx(a)`` for ``rotation_deg = (a, b, c)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import cv2
import numpy as np
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class CharucoBoard:
    """A printed ChArUco board (``[camera.*_board]`` of session.toml, without placement)."""

    squares: tuple[int, int]  # squares_x, squares_y
    square_mm: float
    marker_mm: float
    dictionary: str = "DICT_5X5_250"  # a cv2.aruco predefined dictionary name
    first_marker_id: int = 0
    legacy_pattern: bool = False

    def __post_init__(self) -> None:
        sx, sy = self.squares
        if sx < 2 or sy < 2:
            raise ValueError(f"a ChArUco board needs at least 2 x 2 squares, got {sx} x {sy}")
        if not 0 < self.marker_mm < self.square_mm:
            raise ValueError(
                f"marker_mm ({self.marker_mm}) must be positive and smaller than square_mm "
                f"({self.square_mm})"
            )
        if not hasattr(cv2.aruco, self.dictionary):
            raise ValueError(f"unknown cv2.aruco dictionary {self.dictionary!r}")

    def __getstate__(self) -> dict[str, Any]:
        """Picklable (the cached OpenCV board is not): it is rebuilt on first use."""
        state = dict(self.__dict__)
        state.pop("cv_board", None)
        return state

    @property
    def n_markers(self) -> int:
        sx, sy = self.squares
        return (sx * sy) // 2

    @property
    def marker_ids(self) -> np.ndarray:
        return np.arange(self.first_marker_id, self.first_marker_id + self.n_markers)

    @cached_property
    def cv_board(self) -> Any:
        """The ``cv2.aruco.CharucoBoard`` (built once)."""
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard(
            self.squares, self.square_mm, self.marker_mm, d, self.marker_ids.astype(np.int32)
        )
        board.setLegacyPattern(self.legacy_pattern)
        return board

    @cached_property
    def corners_mm(self) -> np.ndarray:
        """Inner chessboard corners in the board frame, (N, 3) mm, indexed by corner id."""
        return np.asarray(self.cv_board.getChessboardCorners(), dtype=float).reshape(-1, 3)

    @property
    def size_mm(self) -> tuple[float, float]:
        return self.squares[0] * self.square_mm, self.squares[1] * self.square_mm


def rotation_matrix(rotation_deg: tuple[float, float, float] | np.ndarray) -> np.ndarray:
    """R = Rz(c) Ry(b) Rx(a) for (a, b, c) degrees (extrinsic x, y, z)."""
    return np.asarray(
        Rotation.from_euler("xyz", np.asarray(rotation_deg), degrees=True).as_matrix()
    )


@dataclass(frozen=True)
class ReferenceBoard:
    """The board fixed to the base: it defines the base frame."""

    board: CharucoBoard
    origin: tuple[float, float, float]
    rotation_deg: tuple[float, float, float] = (180.0, 0.0, 0.0)

    @property
    def rotation(self) -> np.ndarray:
        return rotation_matrix(self.rotation_deg)

    @property
    def corners_base(self) -> np.ndarray:
        """Its corners in the base frame, (N, 3) mm."""
        return np.asarray(self.board.corners_mm @ self.rotation.T + np.asarray(self.origin))


@dataclass(frozen=True)
class EffectorBoard:
    """The board fixed to the effector; ``offset`` is B in the board's own frame (mm)."""

    board: CharucoBoard
    offset: tuple[float, float, float]
    # the uncertainty of the offset as printed and mounted (mm per coordinate): a constant
    # vector no identification sees, counted by the trust gate
    offset_sigma_mm: float = 0.0


@dataclass(frozen=True)
class CameraSetup:
    """Both boards of a session (the ``[camera]`` section without the intrinsics)."""

    reference: ReferenceBoard
    effector: EffectorBoard
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        shared = set(self.reference.board.marker_ids.tolist()) & set(
            self.effector.board.marker_ids.tolist()
        )
        if shared and self.reference.board.dictionary == self.effector.board.dictionary:
            raise ValueError(
                f"the reference and effector boards share marker ids ({min(shared)}...): "
                "their ids must be disjoint"
            )
