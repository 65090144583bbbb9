"""Effector positions from pictures, frame by frame: reference board -> camera -> effector
board -> offset -> B in the base frame, with the covariance of each B.

A frame where a board is not seen well (too few corners, too blurred, a reprojection error
too large) is skipped and counted with its reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.camera.boards import CameraSetup
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.intrinsics import Intrinsics


@dataclass(frozen=True)
class FrameQuality:
    """When a board is seen well enough in a frame."""

    min_corners: int = 6
    min_sharpness: float = 0.0  # variance of the Laplacian; 0 = not checked
    max_reprojection_px: float = 1.5


@dataclass(frozen=True, eq=False)
class FramePositions:
    """Per frame: ``positions`` (F, 3) B in the base frame (NaN when skipped),
    ``covariances`` (F, 3, 3) from the corner noise; ``skipped`` (F,) '' or the reason,
    naming the board ('reference' | 'effector')."""

    positions: np.ndarray
    covariances: np.ndarray
    skipped: tuple[str, ...]

    @property
    def valid(self) -> np.ndarray:
        return np.array([s == "" for s in self.skipped], dtype=bool)


def effector_positions(
    reference: list[BoardDetection | None],
    effector: list[BoardDetection | None],
    setup: CameraSetup,
    intrinsics: Intrinsics,
    quality: FrameQuality | None = None,
) -> FramePositions:
    """Each frame solved on its own (the baseline; the session-level fit of
    :mod:`.session_fit` is far more accurate)."""
    raise NotImplementedError
