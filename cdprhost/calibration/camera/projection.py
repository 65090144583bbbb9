"""The pinhole camera with OpenCV's distortion, vectorised (for bundle adjustment).

``project(points_cam, v)`` maps camera-frame points (..., 3) to pixels (..., 2) with the
intrinsics vector ``v`` = (fx, fy, cx, cy, k1, k2, p1, p2, k3), the model of
``cv2.projectPoints``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def project(points_cam: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Pixels (..., 2) of camera-frame points (..., 3) (OpenCV's model)."""
    p = np.asarray(points_cam, float)
    x = p[..., 0] / p[..., 2]
    y = p[..., 1] / p[..., 2]
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = v
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([fx * xd + cx, fy * yd + cy], axis=-1)


def rotvec_matrix(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a rotation vector (OpenCV's Rodrigues)."""
    return np.asarray(Rotation.from_rotvec(np.asarray(rvec, float).ravel()).as_matrix())


def to_camera(points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """``R(rvec) p + tvec`` for points (..., 3)."""
    return np.asarray(points @ rotvec_matrix(rvec).T + np.asarray(tvec, float).ravel())
