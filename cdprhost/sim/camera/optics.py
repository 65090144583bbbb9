"""A pinhole camera with OpenCV's lens distortion, placed in the machine's base frame.

``PinholeCamera`` holds the image size, the matrix ``K``, the distortion
``(k1, k2, p1, p2, k3)`` and the pose ``x_cam = R x_base + t``. :meth:`project` maps
base-frame points to pixels (the forward model, as ``cv2.projectPoints``);
:meth:`rays` maps pixels back to undistorted normalised rays (the inverse of the
distortion, solved by Newton's method per pixel), which the renderer intersects with
the board planes. Pure numpy, vectorised over points.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Rotation base -> camera of a camera at ``eye`` looking at ``target`` (OpenCV axes:
    x right, y down, z forward), ``up`` appearing upward in the image."""
    e, g = np.asarray(eye, dtype=float), np.asarray(target, dtype=float)
    z = (g - e) / np.linalg.norm(g - e)
    x = np.cross(z, np.asarray(up, dtype=float))
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, np.array([0.0, 1.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.vstack([x, y, z])


def rotation_xyz(degrees: Sequence[float]) -> np.ndarray:
    """``Rz(c) Ry(b) Rx(a)`` for ``[a, b, c]`` (the session's ``rotation_deg``)."""
    a, b, c = np.radians(np.asarray(degrees, dtype=float).reshape(3))
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


def distort(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """OpenCV's distortion of normalised points (..., 2)."""
    k1, k2, p1, p2, k3 = dist
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def undistort(xy_d: np.ndarray, dist: np.ndarray, iterations: int = 12) -> np.ndarray:
    """Normalised undistorted points whose distortion is ``xy_d`` (Newton's method with a
    numerical Jacobian; NaN where it does not converge to 1e-9)."""
    xy = xy_d.astype(float).copy()
    h = 1e-7
    for _ in range(iterations):
        f = distort(xy, dist) - xy_d
        fx = (distort(xy + [h, 0.0], dist) - xy_d - f) / h
        fy = (distort(xy + [0.0, h], dist) - xy_d - f) / h
        det = fx[..., 0] * fy[..., 1] - fy[..., 0] * fx[..., 1]
        dx = (fy[..., 1] * f[..., 0] - fy[..., 0] * f[..., 1]) / det
        dy = (-fx[..., 1] * f[..., 0] + fx[..., 0] * f[..., 1]) / det
        xy[..., 0] -= dx
        xy[..., 1] -= dy
    bad = np.linalg.norm(distort(xy, dist) - xy_d, axis=-1) > 1e-9
    xy[bad] = np.nan
    return xy


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """Image size (width, height) px, matrix ``K``, distortion ``(k1, k2, p1, p2, k3)``,
    pose base -> camera (``rotation``, ``translation`` mm)."""

    image_size: tuple[int, int]
    matrix: np.ndarray
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_fov(
        cls,
        image_size: tuple[int, int],
        hfov_deg: float,
        distortion: Sequence[float] = (0.0, 0.0, 0.0, 0.0, 0.0),
        *,
        aspect: float = 1.0,
        principal_offset: tuple[float, float] = (0.0, 0.0),
    ) -> PinholeCamera:
        """A camera whose horizontal field of view is ``hfov_deg`` (undistorted)."""
        w, h = image_size
        fx = (w / 2) / math.tan(math.radians(hfov_deg) / 2)
        k = np.array(
            [
                [fx, 0.0, (w - 1) / 2 + principal_offset[0]],
                [0.0, fx * aspect, (h - 1) / 2 + principal_offset[1]],
                [0.0, 0.0, 1.0],
            ]
        )
        return cls((int(w), int(h)), k, np.asarray(distortion, dtype=float).reshape(5))

    def placed(self, eye: ArrayLike, target: ArrayLike) -> PinholeCamera:
        """This camera at ``eye`` (base frame, mm) looking at ``target``."""
        r = look_at(eye, target)
        return PinholeCamera(
            self.image_size, self.matrix, self.distortion, r, -r @ np.asarray(eye, float)
        )

    @property
    def position(self) -> np.ndarray:
        """The camera's centre in the base frame (mm)."""
        return -self.rotation.T @ self.translation

    def to_camera(self, points_base: ArrayLike) -> np.ndarray:
        return np.asarray(points_base, dtype=float) @ self.rotation.T + self.translation

    def project_camera(self, points_cam: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) of camera-frame points (..., 3); NaN behind the camera."""
        z = points_cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = points_cam[..., :2] / np.where(z > 1e-9, z, np.nan)[..., None]
        d = distort(xy, self.distortion)
        k = self.matrix
        u = k[0, 0] * d[..., 0] + k[0, 1] * d[..., 1] + k[0, 2]
        v = k[1, 1] * d[..., 1] + k[1, 2]
        return np.stack([u, v], axis=-1)

    def project(self, points_base: ArrayLike) -> np.ndarray:
        """Pixels (..., 2) of base-frame points (..., 3)."""
        return self.project_camera(self.to_camera(points_base))

    def rays(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (..., 2) of the pixels ``(u, v)`` (pixel
        centres at integers, as OpenCV); NaN where the lens model does not invert."""
        k = self.matrix
        y = (v - k[1, 2]) / k[1, 1]
        x = (u - k[0, 2] - k[0, 1] * y) / k[0, 0]
        return undistort(np.stack([x, y], axis=-1), self.distortion)

    def in_image(self, pixels: np.ndarray, margin: float = 0.0) -> np.ndarray:
        w, h = self.image_size
        u, v = pixels[..., 0], pixels[..., 1]
        return (u >= margin) & (u <= w - 1 - margin) & (v >= margin) & (v <= h - 1 - margin)
