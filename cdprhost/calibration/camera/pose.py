"""One board's pose from one detection (PnP), with its covariance from the corner noise."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.intrinsics import Intrinsics


@dataclass(frozen=True, eq=False)
class BoardPose:
    """board -> camera: ``p_cam = R p_board + t``. ``rvec``, ``tvec`` (3,) each;
    ``covariance`` (6, 6) of (rvec, tvec) from the corner noise (``pixel_sigma`` px,
    estimated from the residuals when not given); ``rms_px`` reprojection error;
    ``n_corners``."""

    rvec: np.ndarray
    tvec: np.ndarray
    covariance: np.ndarray
    rms_px: float
    n_corners: int

    @property
    def rotation(self) -> np.ndarray:
        from cdprhost.calibration.camera.projection import rotvec_matrix

        return rotvec_matrix(self.rvec)


def solve_board_pose(
    detection: BoardDetection,
    board: CharucoBoard,
    intrinsics: Intrinsics,
    pixel_sigma: float | None = None,
) -> BoardPose | None:
    """PnP of a detection (at least 4 non-collinear corners), or None when it cannot be
    solved."""
    raise NotImplementedError
