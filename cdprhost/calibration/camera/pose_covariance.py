"""How sure the camera's pose is, and what that does to every position measured in the base
frame: the reference board's corners give the camera pose a covariance (block jackknifes
over rows and columns of corners, or the formal one), and a camera pose error is a rigid
error of the whole base frame, the same for every pose (a systematic part no take's frame
scatter shows)."""

from __future__ import annotations

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.projection import rotvec_matrix

MIN_PIXEL_SIGMA = 0.03  # px: a detector is never better than this, however well it fits


def camera_pose_covariance(
    ids: np.ndarray,
    obj: np.ndarray,
    px: np.ndarray,
    board: CharucoBoard,
    v: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
) -> np.ndarray:
    """Covariance (6, 6) of the camera pose (rvec, tvec) from the reference board's corners:
    block jackknifes over the board's columns and over its rows of corners, added (the
    errors of neighbouring corners are alike: lens model, detector bias, printing, so the
    formal covariance of independent corners is too small), or the formal one from the
    residuals, whichever is larger."""
    k = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1]])
    dist = v[4:9]
    xy = board.corners_mm[ids, :2]
    x0 = np.concatenate([rvec, tvec])
    proj, jac = cv2.projectPoints(obj, rvec, tvec, k, dist)
    resid = proj.reshape(-1, 2) - px
    dof = max(resid.size - 6, 1)
    s2 = max(float(np.sum(resid**2)) / dof, MIN_PIXEL_SIGMA**2)
    j = np.asarray(jac, float)[:, :6]
    formal = s2 * np.linalg.pinv(j.T @ j)
    jacks = []
    for axis in (0, 1):  # delete one column of corners at a time, then one row
        est = []
        for value in np.unique(xy[:, axis]):
            keep = xy[:, axis] != value
            if keep.sum() < 6:
                continue
            r, t = cv2.solvePnPRefineLM(obj[keep], px[keep], k, dist, rvec.copy(), tvec.copy())
            est.append(np.concatenate([np.ravel(r), np.ravel(t)]) - x0)
        g = len(est)
        if g >= 3:
            dev = np.array(est) - np.mean(est, axis=0)
            jacks.append((g - 1) / g * (dev.T @ dev))
    if not jacks:
        return formal
    # deleting rows sees errors that differ from row to row, deleting columns those that
    # differ from column to column; a pattern may do both, so the two parts add
    jack = np.sum(jacks, axis=0)
    return jack if np.trace(jack[3:, 3:]) > np.trace(formal[3:, 3:]) else formal


def frame_covariance(rvec: np.ndarray, tvec: np.ndarray, camera_cov: np.ndarray) -> np.ndarray:
    """The camera pose's covariance as a rigid error of the base frame: dB = w x B + t
    for every measured B, (6, 6) of (w, t)."""
    r = rotvec_matrix(rvec)
    probe = np.array([[0, 0, 150.0], [150, 0, 150], [0, 150, 150], [0, 0, 300], [-150, -100, 250]])
    cam_pts = probe @ r.T + tvec

    def to_base(x: np.ndarray) -> np.ndarray:
        rr = rotvec_matrix(x[:3])
        return np.asarray((cam_pts - x[3:]) @ rr)

    x0 = np.concatenate([rvec, tvec])
    design = np.concatenate([np.hstack([-skew(p), np.eye(3)]) for p in probe])
    mapping = np.empty((6, 6))
    for j in range(6):
        h = 1e-6 if j < 3 else 1e-3
        step = np.zeros(6)
        step[j] = h
        d_b = (to_base(x0 + step) - to_base(x0 - step)).ravel() / (2 * h)
        mapping[:, j] = np.linalg.lstsq(design, d_b, rcond=None)[0]
    return np.asarray(mapping @ camera_cov @ mapping.T)


def skew(a: np.ndarray) -> np.ndarray:
    """[a]x such that [a]x b = a x b; a small rotation w moves R p by w x (R p) = -[Rp]x w."""
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
