"""How well do the intrinsics place a point in the image? The predicted reprojection
uncertainty: the intrinsics' covariance carried to the pixel where a ray lands.

A calibration is judged by it where it matters, where the machine's boards will be seen:
views that never reach one corner of the image leave the lens poorly known there and
nowhere else, and a machine whose boards sit in the middle of the picture does not care.
A whole-image map of it says where views would help.
"""

from __future__ import annotations

import cv2
import numpy as np

from cdprhost.calibration.camera.projection import project


def reprojection_sd(
    vector: np.ndarray, covariance: np.ndarray, points_px: np.ndarray
) -> np.ndarray:
    """Per point (N,) px: the standard deviation along the worst image direction of where
    a point seen at ``points_px`` (N, 2) lands, from the intrinsics ``vector`` (9,) and
    their ``covariance`` (9, 9), after the pose of the points (one rigid body, the
    region's points on the plane at unit depth) has taken up what it can: a principal
    point or focal length error that merely shifts or scales the picture is a pose error,
    absorbed by every board's own pose; a lens known poorly in one corner is not."""
    v = np.asarray(vector, float)
    pts = np.asarray(points_px, float).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros(0)
    k = np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]])
    xy = cv2.undistortPointsIter(
        pts.reshape(-1, 1, 2),
        k,
        v[4:9],
        np.eye(3),
        np.eye(3),
        (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 40, 1e-10),
    ).reshape(-1, 2)
    rays = np.c_[xy, np.ones(len(xy))]
    base = project(rays, v)
    jac = np.zeros((len(pts), 2, 9))
    for i in range(9):
        step = 1e-6 * max(abs(v[i]), 1.0)
        dv = v.copy()
        dv[i] += step
        jac[:, :, i] = (project(rays, dv) - base) / step
    # the pose's six directions (small rotation, translation) and the projector off them
    pose = np.zeros((len(pts), 2, 6))
    for i in range(6):
        moved = rays.copy()
        e = np.zeros(3)
        e[i % 3] = 1e-6
        moved = moved + np.cross(e, rays) if i < 3 else moved + e
        pose[:, :, i] = (project(moved, v) - base) / 1e-6
    jp = pose.reshape(-1, 6)
    proj = np.eye(jp.shape[0]) - jp @ np.linalg.pinv(jp)
    cov = proj @ jac.reshape(-1, 9) @ np.asarray(covariance, float) @ jac.reshape(-1, 9).T @ proj
    cov_px = np.stack([cov[2 * n : 2 * n + 2, 2 * n : 2 * n + 2] for n in range(len(pts))])
    return np.sqrt(np.clip(np.linalg.eigvalsh(cov_px)[:, -1], 0.0, None))


def middle_region(image_size: tuple[int, int], fraction: float = 0.6, n: int = 9) -> np.ndarray:
    """Points (n*n, 2) px over the middle ``fraction`` of the image: where a machine's
    boards are seen when nothing else says so."""
    w, h = image_size
    u = w / 2 + (np.linspace(-0.5, 0.5, n) * fraction) * w
    v = h / 2 + (np.linspace(-0.5, 0.5, n) * fraction) * h
    uu, vv = np.meshgrid(u, v)
    return np.c_[uu.ravel(), vv.ravel()]


def cell_centres(image_size: tuple[int, int], grid: int) -> np.ndarray:
    """(grid, grid, 2) px: the centres of a grid x grid division of the image."""
    w, h = image_size
    u = (np.arange(grid) + 0.5) / grid * w
    v = (np.arange(grid) + 0.5) / grid * h
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu, vv], axis=-1)
