"""One board's pose from one detection (PnP), with its covariance from the corner noise."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.intrinsics import Intrinsics

#: Fewest corners for a pose (a plane's homography needs 4).
MIN_CORNERS = 4
#: Floor of the corner noise estimated from residuals (px): a handful of corners can fit
#: almost exactly by chance.
MIN_PIXEL_SIGMA = 0.05


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
    if len(detection) < MIN_CORNERS:
        return None
    obj = board.corners_mm[detection.ids].astype(np.float64)
    img = detection.corners_px.astype(np.float64)
    k = np.asarray(intrinsics.matrix, np.float64)
    dist = intrinsics.distortion_5
    try:
        ok, rvec, tvec = cv2.solvePnP(obj, img, k, dist, flags=cv2.SOLVEPNP_IPPE)
    except cv2.error:
        return None
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, dist, rvec, tvec)
    proj, jac = cv2.projectPoints(obj, rvec, tvec, k, dist)
    resid = proj.reshape(-1, 2) - img
    n = img.shape[0]
    rms = float(np.sqrt(np.mean(np.sum(resid**2, axis=1))))
    if pixel_sigma is None:
        dof = max(2 * n - 6, 1)
        pixel_sigma = max(float(np.sqrt(np.sum(resid**2) / dof)), MIN_PIXEL_SIGMA)
    j = np.asarray(jac, float)[:, :6]
    try:
        cov = pixel_sigma**2 * np.linalg.inv(j.T @ j)
    except np.linalg.LinAlgError:
        cov = np.full((6, 6), np.inf)
    return BoardPose(np.asarray(rvec, float).ravel(), np.asarray(tvec, float).ravel(), cov, rms, n)
