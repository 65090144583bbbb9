"""The session-level fit: one camera pose, one effector-board orientation and (where the
data make them observable) refined intrinsics, jointly with the 12 geometric parameters,
from the raw corners of every frame, with the robot's commanded motion as constraint.

Stages: (1) camera pose from every reference-board corner of the session; (2) one
effector-board orientation with a free translation per pose (no kinematics); (3) bundle
adjustment: intrinsics (the observable subset), camera pose, board orientation and the
12 parameters, the effector board at ``B_k = FK(q, s_k)``; (4) each frame's B re-solved
(3 unknowns) with the session-level camera, fed to the take test; each pose's covariance
is the corner noise plus the camera parameters' uncertainty carried to it; the board
orientation's uncertainty times the offset is a constant vector (``common_covariance``)
no identification sees, which the trust gate adds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdprhost.calibration.camera.boards import CameraSetup
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.intrinsics import Intrinsics
from cdprhost.kinematics.machine import MachineModel


@dataclass(frozen=True, eq=False)
class TakeDetections:
    """The detections of one take (one pose): per frame, each board's or None."""

    reference: tuple[BoardDetection | None, ...]
    effector: tuple[BoardDetection | None, ...]
    times_s: np.ndarray | None = None  # (F,) frame times; default 0, 1/30, ...


@dataclass(frozen=True, eq=False)
class SessionFit:
    """What the session-level fit found.

    ``frame_positions``: per pose, (F, 3) B of every frame (NaN when skipped);
    ``frame_skipped``: per pose, per frame '' or the reason (naming the board);
    ``positions`` (K, 3) each pose's B (mean of its frames, NaN when none);
    ``covariances`` (K, 3, 3) each pose's accuracy (corner noise + camera parameters);
    ``common_covariance`` (3, 3) of the vector shared by every B (board orientation x
    offset, offset as printed); ``intrinsics`` (refined); ``camera_rvec``, ``camera_tvec``
    base -> camera; ``effector_rotation`` (3, 3) board -> base; ``refined`` names of the
    intrinsics refined; ``notes`` (what was not observable, and why); ``geometry_q`` (12,)
    from the bundle adjustment (or None when it was not run)."""

    frame_positions: tuple[np.ndarray, ...]
    frame_skipped: tuple[tuple[str, ...], ...]
    positions: np.ndarray
    covariances: np.ndarray
    common_covariance: np.ndarray
    intrinsics: Intrinsics
    camera_rvec: np.ndarray
    camera_tvec: np.ndarray
    effector_rotation: np.ndarray
    pixel_sigma: float
    refined: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    geometry_q: np.ndarray | None = None
    extra: dict[str, float] = field(default_factory=dict)


def fit_session(
    takes: list[TakeDetections],
    setup: CameraSetup,
    intrinsics: Intrinsics,
    sliders: np.ndarray | None = None,
    model: MachineModel | None = None,
    *,
    refine: tuple[str, ...] | None = None,
) -> SessionFit:
    """The session-level fit. With ``sliders`` (K, 3) commanded and ``model`` (the
    profile's), the bundle adjustment refines the intrinsics named in ``refine`` (default:
    focal length and k1 where observable) jointly with the 12 parameters; without them,
    stages 1, 2 and 4 only (camera-only positions)."""
    raise NotImplementedError
