"""Calibration with one camera and printed ChArUco boards (camera-session.md): the pure
estimation core. Images come in as numpy arrays; nothing here reads or writes files.

- :mod:`.boards`: boards and their placement;
- :mod:`.detection`: corners of a board in an image;
- :mod:`.intrinsics`: intrinsics from calibration views, with coverage check and std;
- :mod:`.bowed_fit`: the lens fitted with the printed sheet's bow, and only the distortion
  terms the views observe;
- :mod:`.reprojection_uncertainty`: how well the intrinsics place a point, where it matters;
- :mod:`.projection`: the camera model, vectorised;
- :mod:`.pose`: one board's pose (PnP) with covariance;
- :mod:`.positions`: per-frame effector positions (the baseline);
- :mod:`.session_fit`: the session-level fit (one camera pose, one board orientation,
  intrinsics refined with the robot's motion) and each pose's B with its covariance;
- :mod:`.take_drift`: a camera take's drift tested on the camera's own frame noise.
"""

from cdprhost.calibration.camera.boards import (
    CameraSetup,
    CharucoBoard,
    EffectorBoard,
    ReferenceBoard,
)
from cdprhost.calibration.camera.detection import BoardDetection, DetectorSettings, detect_board
from cdprhost.calibration.camera.intrinsics import (
    Coverage,
    Intrinsics,
    IntrinsicsResult,
    calibrate_intrinsics,
)
from cdprhost.calibration.camera.pose import BoardPose, solve_board_pose
from cdprhost.calibration.camera.positions import FramePositions, FrameQuality, effector_positions
from cdprhost.calibration.camera.session_fit import SessionFit, TakeDetections, fit_session

__all__ = [
    "BoardDetection",
    "BoardPose",
    "CameraSetup",
    "CharucoBoard",
    "Coverage",
    "DetectorSettings",
    "EffectorBoard",
    "FramePositions",
    "FrameQuality",
    "Intrinsics",
    "IntrinsicsResult",
    "ReferenceBoard",
    "SessionFit",
    "TakeDetections",
    "calibrate_intrinsics",
    "detect_board",
    "effector_positions",
    "fit_session",
    "solve_board_pose",
]
