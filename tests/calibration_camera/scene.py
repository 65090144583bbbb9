"""A camera calibration scene for the estimation tests: a true machine, both boards, a
camera, and the corners it sees at each pose (projected analytically with noise, or
rendered and detected)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from cdprhost.calibration.camera.boards import (
    CameraSetup,
    CharucoBoard,
    EffectorBoard,
    ReferenceBoard,
)
from cdprhost.calibration.camera.detection import BoardDetection, detect_board
from cdprhost.calibration.camera.intrinsics import Intrinsics
from cdprhost.calibration.camera.projection import project
from cdprhost.calibration.camera.session_fit import TakeDetections
from cdprhost.kinematics.machine import MachineModel
from cdprhost.sim.measurement import achieved_points
from tests.calibration_camera.render import look_at, render

REFERENCE = ReferenceBoard(
    CharucoBoard((7, 5), 30.0, 22.0, "DICT_5X5_250", 0), (-105.0, 75.0, 3.0), (180.0, 0.0, 0.0)
)
EFFECTOR_BOARD = CharucoBoard((5, 4), 16.0, 12.0, "DICT_5X5_250", 100)


def camera_intrinsics(
    size: tuple[int, int] = (1920, 1080), hfov_deg: float = 70.0, k1: float = -0.08
) -> Intrinsics:
    f = size[0] / 2 / np.tan(np.radians(hfov_deg / 2))
    k = np.array([[f, 0, size[0] / 2 - 0.5 + 4], [0, f, size[1] / 2 - 0.5 - 3], [0, 0, 1]])
    return Intrinsics(k, np.array([k1, 0.03, 0.0, 0.0, 0.0]), size)


@dataclass(frozen=True)
class Scene:
    setup: CameraSetup
    intrinsics: Intrinsics  # the truth
    cam_rot: np.ndarray  # base -> camera
    cam_t: np.ndarray
    eff_rot: np.ndarray  # effector board -> base

    def corners(self, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """True pixels of the reference corners and of the effector corners with B at ``b``."""
        ref = self.setup.reference.corners_base
        off = np.asarray(self.setup.effector.offset)
        eff = (self.setup.effector.board.corners_mm - off) @ self.eff_rot.T + b
        v = self.intrinsics.vector
        return (
            project(ref @ self.cam_rot.T + self.cam_t, v),
            project(eff @ self.cam_rot.T + self.cam_t, v),
        )

    def board_poses(self, b: np.ndarray) -> list[tuple[CharucoBoard, np.ndarray, np.ndarray]]:
        ref = self.setup.reference
        off = np.asarray(self.setup.effector.offset)
        r_ref = self.cam_rot @ ref.rotation
        t_ref = self.cam_rot @ np.asarray(ref.origin) + self.cam_t
        origin = b - self.eff_rot @ off
        r_eff = self.cam_rot @ self.eff_rot
        t_eff = self.cam_rot @ origin + self.cam_t
        return [(ref.board, r_ref, t_ref), (self.setup.effector.board, r_eff, t_eff)]


def make_scene(
    intr: Intrinsics | None = None,
    distance_mm: float = 700.0,
    elevation_deg: float = 40.0,
    board_tilt_deg: tuple[float, float] = (15.0, -10.0),
    offset: tuple[float, float, float] = (40.0, 36.0, 69.0),
) -> Scene:
    intr = intr or camera_intrinsics()
    target = np.array([0.0, 0.0, 170.0])
    el = np.radians(elevation_deg)
    eye = target + distance_mm * np.array([0.0, -np.cos(el), np.sin(el)])
    rot, t = look_at(eye, target, np.array([0.0, 0.0, 1.0]))
    # the effector board faces the camera (its z axis points away from it), a little tilted
    face = rot.T  # camera axes in the base: columns x, y, z
    tilt = Rotation.from_euler("xy", board_tilt_deg, degrees=True).as_matrix()
    eff_rot = face @ tilt
    setup = CameraSetup(REFERENCE, EffectorBoard(EFFECTOR_BOARD, offset))
    return Scene(setup, intr, rot, t, eff_rot)


def _detection(ids: np.ndarray, px: np.ndarray, size: tuple[int, int]) -> BoardDetection | None:
    w, h = size
    inside = np.all((px > 8) & (px < np.array([w - 9, h - 9])), axis=1)
    if inside.sum() < 4:
        return None
    return BoardDetection(ids[inside], px[inside], int(inside.sum() // 2), 1000.0, size)


def analytic_takes(
    scene: Scene,
    points: np.ndarray,
    frames: int,
    rng: np.random.Generator,
    sigma_px: float = 0.08,
    bias_px: float = 0.04,
) -> list[TakeDetections]:
    """Per pose, ``frames`` frames of both boards' corners: the truth plus a static error per
    corner (``bias_px``, the same in every frame of a take: detector bias) plus frame noise."""
    size = scene.intrinsics.image_size
    ref_bias = rng.normal(0, bias_px, (len(scene.setup.reference.board.corners_mm), 2))
    out = []
    for b in points:
        ref, eff = scene.corners(b)
        eff_bias = rng.normal(0, bias_px, eff.shape)
        refs, effs = [], []
        for _ in range(frames):
            r = ref + ref_bias + rng.normal(0, sigma_px, ref.shape)
            e = eff + eff_bias + rng.normal(0, sigma_px, eff.shape)
            refs.append(_detection(np.arange(len(r)), r, size))
            effs.append(_detection(np.arange(len(e)), e, size))
        out.append(TakeDetections(tuple(refs), tuple(effs)))
    return out


def rendered_takes(
    scene: Scene, points: np.ndarray, frames: int, rng: np.random.Generator, **render_options
) -> list[TakeDetections]:
    """Per pose, ``frames`` rendered images, both boards detected."""
    out = []
    for b in points:
        refs, effs = [], []
        for _ in range(frames):
            img = render(scene.board_poses(b), scene.intrinsics, rng=rng, **render_options)
            refs.append(detect_board(img, scene.setup.reference.board))
            effs.append(detect_board(img, scene.setup.effector.board))
        out.append(TakeDetections(tuple(refs), tuple(effs)))
    return out


def workspace_rms(truth: MachineModel, identified: MachineModel, grid: np.ndarray) -> float:
    err = np.linalg.norm(achieved_points(truth, identified, grid) - grid, axis=1)
    return float(np.sqrt(np.mean(err**2)))
