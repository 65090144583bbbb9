"""The camera source: calibration with one camera and printed ChArUco boards
(camera-session.md). Everything camera lives here; like the motion-capture source it ends
in the same observations (each pose's B with its covariance) that identification takes.

The pure estimation core (images come in as numpy arrays):

- :mod:`.boards`: boards and their placement;
- :mod:`.detection`: corners of a board in an image;
- :mod:`.intrinsics`: intrinsics from calibration views, with coverage check and std;
- :mod:`.bowed_fit`: the lens fitted with the printed sheet's bow, and only the distortion
  terms the views observe;
- :mod:`.reprojection_uncertainty`: how well the intrinsics place a point, where it matters;
- :mod:`.projection`: the camera model, vectorised;
- :mod:`.pose`: one board's pose (PnP) with covariance;
- :mod:`.pose_covariance`: the covariance of a board pose from its corners;
- :mod:`.positions`: per-frame effector positions (the baseline);
- :mod:`.bundle_adjustment`, :mod:`.session_fit`: the session-level fit (one camera pose,
  one board orientation, intrinsics refined with the robot's motion) and each pose's B
  with its covariance;
- :mod:`.take_drift`: a camera take's drift tested on the camera's own frame noise;
- :mod:`.take_scatter`: its frames' scatter tested on the same noise;
- :mod:`.visibility`: which board corners a camera placement can see.

The shell around it (files, devices): :mod:`.config` (the ``[camera]`` table and
camera.toml), :mod:`.printable` (boards to print), :mod:`.capture` (frames from a device),
:mod:`.takes` (a session's pictures read and detected) and :mod:`.session` (a camera
session measured into the session's measurements).
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
