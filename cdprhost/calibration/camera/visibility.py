"""Which poses a camera can measure: pose planning for camera sessions.

Before the first move the wizard looks once: the reference board gives the camera's pose
in the base frame, the effector board its orientation (:func:`view_from_poses`). A
candidate pose is kept (:func:`visible_mask`) when the effector board's sheet lies
inside the image with a margin, faces the camera within ``max_angle_deg`` (more oblique
boards lose corners and accuracy), and does not hide more than ``max_hidden`` of the
reference board's corners. Pure numpy over all candidates at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.camera.boards import CameraSetup, CharucoBoard
from cdprhost.calibration.camera.intrinsics import Intrinsics
from cdprhost.calibration.camera.pose import BoardPose
from cdprhost.calibration.camera.projection import project


@dataclass(frozen=True, eq=False)
class CameraView:
    """The camera (intrinsics; base -> camera ``rotation``, ``translation`` mm) and the
    effector board's orientation (board -> base), as far as they are known."""

    intrinsics: Intrinsics
    rotation: np.ndarray
    translation: np.ndarray
    effector_rotation: np.ndarray

    @property
    def position(self) -> np.ndarray:
        return np.asarray(-self.rotation.T @ self.translation)


def view_from_poses(
    reference: BoardPose, effector: BoardPose, setup: CameraSetup, intrinsics: Intrinsics
) -> CameraView:
    """The camera and the effector board's orientation from one picture of both boards."""
    r_ref = setup.reference.rotation
    rotation = reference.rotation @ r_ref.T
    translation = np.asarray(reference.tvec, float).ravel() - rotation @ np.asarray(
        setup.reference.origin, float
    )
    return CameraView(intrinsics, rotation, translation, rotation.T @ effector.rotation)


def sheet_outline(board: CharucoBoard, margin_squares: float = 0.5) -> np.ndarray:
    """The printed sheet's four corners (with its white margin), board frame (4, 3) mm."""
    m = margin_squares * board.square_mm
    w, h = board.size_mm
    return np.array([[-m, -m, 0.0], [w + m, -m, 0.0], [w + m, h + m, 0.0], [-m, h + m, 0.0]])


def _inside_quads(points: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """(N, P) whether each of P points (P, 2) lies in each of N convex quads (N, 4, 2)."""
    a = quads[:, :, None, :]  # (N, 4, 1, 2)
    b = np.roll(quads, -1, axis=1)[:, :, None, :]
    p = points[None, None, :, :]
    cross = (b[..., 0] - a[..., 0]) * (p[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
        p[..., 0] - a[..., 0]
    )
    return np.asarray((cross >= 0).all(axis=1) | (cross <= 0).all(axis=1))


def visible_mask(
    points: np.ndarray,
    view: CameraView,
    setup: CameraSetup,
    *,
    margin_px: float = 20.0,
    max_angle_deg: float = 60.0,
    max_hidden: float = 0.25,
) -> np.ndarray:
    """(N,) bool: ``B`` at each of ``points`` (N, 3) can be measured from this view."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    r_e = view.effector_rotation
    eff = setup.effector
    origins = pts - r_e @ np.asarray(eff.offset, float)
    corners = origins[:, None, :] + sheet_outline(eff.board) @ r_e.T  # (N, 4, 3)
    cam = corners @ view.rotation.T + view.translation
    v = view.intrinsics.vector
    w, h = view.intrinsics.image_size
    ok = (cam[..., 2] > 1.0).all(axis=1)
    px = project(np.where(cam[..., 2:3] > 1.0, cam, 1.0), v)
    ok &= ((px[..., 0] >= margin_px) & (px[..., 0] <= w - 1 - margin_px)).all(axis=1)
    ok &= ((px[..., 1] >= margin_px) & (px[..., 1] <= h - 1 - margin_px)).all(axis=1)
    to_cam = view.position - corners.mean(axis=1)
    face = -r_e[:, 2]  # the printed face looks along the board's -z
    cos = (to_cam @ face) / np.linalg.norm(to_cam, axis=1)
    ok &= cos >= math.cos(math.radians(max_angle_deg))
    ref_cam = setup.reference.corners_base @ view.rotation.T + view.translation
    ref_px = project(ref_cam, v)
    hidden = _inside_quads(ref_px, px) & (cam[..., 2].max(axis=1)[:, None] < ref_cam[None, :, 2])
    ok &= hidden.mean(axis=1) <= max_hidden
    return np.asarray(ok)
