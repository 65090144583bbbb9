"""The camera set-up around the simulated machine: where the camera and both boards are.

A :class:`CameraRig` is the truth of a camera session: the camera (intrinsics and pose
in the base frame), the reference board fixed to the base (``origin``, ``rotation_deg``
as in the session), the effector board with its true orientation and the offset from it
to ``B`` (board frame). :func:`standard_rig` builds the usual one: a camera at
``distance_mm`` from the workspace centre, looking down at ``elevation_deg``, the
reference board face-up in the middle of the base, the effector board tilted toward the
camera. :meth:`CameraRig.frame` renders one picture with the effector's ``B`` at a point.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from cdprhost.calibration.camera.boards import (
    CameraSetup,
    CharucoBoard,
    EffectorBoard,
    ReferenceBoard,
    rotation_matrix,
)
from cdprhost.calibration.camera.intrinsics import Intrinsics
from cdprhost.calibration.camera.visibility import CameraView, visible_mask
from cdprhost.sim.camera.imaging import Imaging, encode, expose, occlude
from cdprhost.sim.camera.optics import PinholeCamera
from cdprhost.sim.camera.render import PlacedBoard, Renderer

REFERENCE_BOARD = CharucoBoard((7, 5), 30.0, 22.0, "DICT_5X5_250", 0)
EFFECTOR_BOARD = CharucoBoard((5, 4), 16.0, 12.0, "DICT_5X5_250", 100)
CALIBRATION_BOARD = CharucoBoard((9, 6), 25.0, 18.0, "DICT_5X5_250", 150)
DEFAULT_IMAGING = Imaging()
#: The spec's set-up: the reference board face-up in the middle of the base, B 69 mm
#: behind the effector board's printed face.
STANDARD_SETUP = CameraSetup(
    ReferenceBoard(REFERENCE_BOARD, (-105.0, 75.0, 3.0), (180.0, 0.0, 0.0)),
    EffectorBoard(EFFECTOR_BOARD, (40.0, 32.0, 69.0)),
)
WORKSPACE_CENTRE = (0.0, 0.0, 220.0)
#: A decent webcam lens: barrel distortion, the principal point a little off centre.
WEBCAM_DISTORTION = (-0.12, 0.05, 0.0006, -0.0004, -0.01)


@dataclass(frozen=True, eq=False)
class CameraRig:
    """Truth of a camera session (base frame, mm)."""

    camera: PinholeCamera
    setup: CameraSetup = STANDARD_SETUP
    effector_rotation: np.ndarray = field(default_factory=lambda: rotation_matrix((180, 0, 0)))
    imaging: Imaging = field(default_factory=Imaging)

    def reference_board(self) -> PlacedBoard:
        ref = self.setup.reference
        return PlacedBoard(ref.board, ref.rotation, np.asarray(ref.origin, dtype=float))

    def effector_board(self, b_point: ArrayLike) -> PlacedBoard:
        """The effector board when ``B`` is at ``b_point``."""
        eff = self.setup.effector
        origin = np.asarray(b_point, dtype=float) - self.effector_rotation @ np.asarray(
            eff.offset, dtype=float
        )
        return PlacedBoard(eff.board, self.effector_rotation, origin)

    def boards(self, b_point: ArrayLike) -> list[PlacedBoard]:
        return [self.reference_board(), self.effector_board(b_point)]

    def with_imaging(self, **changes: float | int | bool | None) -> CameraRig:
        return replace(self, imaging=replace(self.imaging, **changes))  # type: ignore[arg-type]

    def renderer(self, supersample: int = 2, seed: int = 0) -> Renderer:
        return Renderer(self.camera, supersample=supersample, seed=seed)

    def picture(
        self,
        renderer: Renderer,
        b_point: ArrayLike,
        rng: np.random.Generator,
        occluders: Sequence[np.ndarray] = (),
    ) -> np.ndarray:
        """One 8-bit picture (before compression) with ``B`` at ``b_point``."""
        light = renderer.radiance(self.boards(b_point))
        occlude(light, occluders)
        return expose(light, self.imaging, rng)

    def frame(
        self,
        renderer: Renderer,
        b_point: ArrayLike,
        rng: np.random.Generator,
        occluders: Sequence[np.ndarray] = (),
    ) -> bytes:
        """One stored picture (JPEG or PNG bytes, :attr:`Imaging.extension`)."""
        return encode(self.picture(renderer, b_point, rng, occluders), self.imaging)

    def view(self) -> CameraView:
        """The truth as the planner's :class:`CameraView`."""
        cam = self.camera
        intr = Intrinsics(np.asarray(cam.matrix), np.asarray(cam.distortion), cam.image_size)
        return CameraView(intr, cam.rotation, cam.translation, self.effector_rotation)

    def visible(self, b_points: ArrayLike, **limits: float) -> np.ndarray:
        """Per point (N,): the camera can measure ``B`` there
        (:func:`~cdprhost.calibration.camera.visibility.visible_mask`)."""
        return visible_mask(np.asarray(b_points, dtype=float), self.view(), self.setup, **limits)


def tilted_toward(camera_position: ArrayLike, at: ArrayLike, fraction: float = 0.6) -> np.ndarray:
    """A board rotation whose printed face points between straight up and the camera
    (``fraction`` of the way to the camera), edges kept level-ish."""
    to_cam = np.asarray(camera_position, float) - np.asarray(at, float)
    to_cam /= np.linalg.norm(to_cam)
    face = (1 - fraction) * np.array([0.0, 0.0, 1.0]) + fraction * to_cam
    face /= np.linalg.norm(face)
    z = -face  # board z points into the board
    x = np.cross(np.array([0.0, 0.0, 1.0]), to_cam)
    x = x - (x @ z) * z
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def standard_rig(
    *,
    image_size: tuple[int, int] = (1920, 1080),
    hfov_deg: float = 70.0,
    distance_mm: float = 700.0,
    elevation_deg: float = 40.0,
    azimuth_deg: float = -90.0,
    distortion: Sequence[float] = WEBCAM_DISTORTION,
    principal_offset: tuple[float, float] = (7.0, -5.0),
    target: Sequence[float] = WORKSPACE_CENTRE,
    effector_tilt: float = 0.6,
    imaging: Imaging = DEFAULT_IMAGING,
    setup: CameraSetup = STANDARD_SETUP,
) -> CameraRig:
    """The usual set-up: a camera ``distance_mm`` from ``target``, ``elevation_deg`` above
    the horizontal, seen from ``azimuth_deg`` (-90: from -y); boards as in the spec."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    direction = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    eye = np.asarray(target, float) + distance_mm * direction
    cam = PinholeCamera.from_fov(
        image_size,
        hfov_deg,
        distortion,
        aspect=1.0004,
        principal_offset=(
            principal_offset[0] * image_size[0] / 1920,
            principal_offset[1] * image_size[0] / 1920,
        ),
    ).placed(eye, target)
    return CameraRig(cam, setup, tilted_toward(eye, target, effector_tilt), imaging)


def phone_rig(**changes: object) -> CameraRig:
    """A phone on a tripod: 1920x1440, a 66 degree lens, 0.5 m, little distortion."""
    options: dict[str, object] = {
        "image_size": (1920, 1440),
        "hfov_deg": 66.0,
        "distance_mm": 500.0,
        "elevation_deg": 45.0,
        "distortion": (0.06, -0.15, 0.0002, 0.0003, 0.1),
        "imaging": Imaging(psf_px=0.9, full_well_e=5000.0, jpeg_quality=88),
    }
    options.update(changes)
    return standard_rig(**options)  # type: ignore[arg-type]


#: Boards with bigger markers (a coarser dictionary) for small pictures.
COARSE_SETUP = CameraSetup(
    ReferenceBoard(CharucoBoard((9, 7), 35.0, 26.0, "DICT_4X4_100", 0), (-157.5, 122.5, 3.0)),
    EffectorBoard(CharucoBoard((4, 3), 30.0, 22.0, "DICT_4X4_100", 40), (60.0, 45.0, 69.0)),
)


def rig_for_size(size: tuple[int, int]) -> CameraRig:
    """The standard rig at ``size``; below 1280 px wide, the coarse boards and a narrower
    lens (tests, quick demos)."""
    if size[0] >= 1280:
        return standard_rig(image_size=size)
    return standard_rig(image_size=size, hfov_deg=60.0, distance_mm=750.0, setup=COARSE_SETUP)


def occluder_over(
    rig: CameraRig, b_point: ArrayLike, fraction: float, board: str = "effector", side: int = 0
) -> np.ndarray:
    """A polygon (4, 2) px hiding ``fraction`` of a board's image from one ``side``
    (0 left, 1 right, 2 top, 3 bottom), as a cable or a hand would."""
    placed = rig.effector_board(b_point) if board == "effector" else rig.reference_board()
    px = rig.camera.project(placed.outline())
    (x0, y0), (x1, y1) = px.min(axis=0), px.max(axis=0)
    f = float(np.clip(fraction, 0.0, 1.0))
    if side == 0:
        x1 = x0 + f * (x1 - x0)
    elif side == 1:
        x0 = x1 - f * (x1 - x0)
    elif side == 2:
        y1 = y0 + f * (y1 - y0)
    else:
        y0 = y1 - f * (y1 - y0)
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
