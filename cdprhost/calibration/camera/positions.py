"""Effector positions from pictures, frame by frame: reference board -> camera -> effector
board -> offset -> B in the base frame, with the covariance of each B.

A frame where a board is not seen well (too few corners, too blurred, a reprojection error
too large) is skipped and counted with its reason. A few corners far off the board's own
pose are dropped first (:func:`without_stray_corners`): a board partly hidden behind
another (the effector in front of the reference board) gets its corners next to the
hiding edge pulled by that edge, and they, not the frame, are what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CameraSetup, CharucoBoard
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.intrinsics import Intrinsics
from cdprhost.calibration.camera.pose import solve_board_pose
from cdprhost.calibration.camera.projection import rotvec_matrix


@dataclass(frozen=True)
class FrameQuality:
    """When a board is seen well enough in a frame."""

    min_corners: int = 6
    min_sharpness: float = 0.0  # variance of the Laplacian; 0 = not checked
    max_reprojection_px: float = 1.5
    # a corner this far (px) from where its board's pose puts it is a stray ...
    max_corner_px: float = 1.0
    # ... and at most this share of a board's corners are dropped as strays
    max_stray_fraction: float = 0.25


@dataclass(frozen=True, eq=False)
class FramePositions:
    """Per frame: ``positions`` (F, 3) B in the base frame (NaN when skipped),
    ``covariances`` (F, 3, 3) from the corner noise; ``skipped`` (F,) '' or the reason,
    naming the board ('reference' | 'effector')."""

    positions: np.ndarray
    covariances: np.ndarray
    skipped: tuple[str, ...]

    @property
    def valid(self) -> np.ndarray:
        return np.array([s == "" for s in self.skipped], dtype=bool)


def without_stray_corners(
    det: BoardDetection | None,
    board: CharucoBoard,
    intr: Intrinsics,
    quality: FrameQuality,
) -> BoardDetection | None:
    """``det`` less the corners its board's pose (solved again after each) puts more than
    ``quality.max_corner_px`` away, worst first, at most ``max_stray_fraction`` of them and
    never below ``min_corners``. A detection with more strays than that is returned as it
    came (:func:`judge_frame` then says what is wrong with it)."""
    if det is None:
        return None
    k = np.asarray(intr.matrix, np.float64)
    keep = np.ones(len(det), bool)
    budget = int(quality.max_stray_fraction * len(det))
    while True:
        cut = _subset(det, keep)
        pose = solve_board_pose(cut, board, intr)
        if pose is None:
            return det
        proj, _ = cv2.projectPoints(
            board.corners_mm[cut.ids].astype(np.float64), pose.rvec, pose.tvec, k, intr.distortion_5
        )
        off = np.linalg.norm(proj.reshape(-1, 2) - cut.corners_px, axis=1)
        worst = int(np.argmax(off))
        if off[worst] <= quality.max_corner_px:
            return cut
        if budget == 0 or keep.sum() <= quality.min_corners:
            return det
        keep[np.flatnonzero(keep)[worst]] = False
        budget -= 1


def _subset(det: BoardDetection, keep: np.ndarray) -> BoardDetection:
    if keep.all():
        return det
    return BoardDetection(
        det.ids[keep], det.corners_px[keep], det.n_markers, det.sharpness, det.image_size
    )


def judge_frame(
    det: BoardDetection | None,
    which: str,
    board_setup: CameraSetup,
    intr: Intrinsics,
    quality: FrameQuality,
) -> str:
    """'' when the board is seen well enough in this frame, else the reason."""
    board = board_setup.reference.board if which == "reference" else board_setup.effector.board
    if det is None:
        return f"{which} board not found"
    if len(det) < quality.min_corners:
        return f"{which} board: {len(det)} corners (need {quality.min_corners})"
    if quality.min_sharpness > 0 and det.sharpness < quality.min_sharpness:
        return f"{which} board blurred (sharpness {det.sharpness:.0f} < {quality.min_sharpness:g})"
    pose = solve_board_pose(det, board, intr)
    if pose is None:
        return f"{which} board: no pose"
    if pose.rms_px > quality.max_reprojection_px:
        return (
            f"{which} board: reprojection error {pose.rms_px:.2f} px "
            f"(limit {quality.max_reprojection_px:g})"
        )
    return ""


def effector_positions(
    reference: list[BoardDetection | None],
    effector: list[BoardDetection | None],
    setup: CameraSetup,
    intrinsics: Intrinsics,
    quality: FrameQuality | None = None,
) -> FramePositions:
    """Each frame solved on its own (the baseline, and the wizard's live check; the
    session-level fit of :mod:`.session_fit` is far more accurate). Each B's covariance
    carries both boards' pose covariances (corner noise) through the composition."""
    q_cfg = quality or FrameQuality()
    n = len(reference)
    if len(effector) != n:
        raise ValueError(f"{n} reference and {len(effector)} effector frames")
    positions = np.full((n, 3), np.nan)
    covariances = np.full((n, 3, 3), np.nan)
    skipped = []
    for i, (r0, e0) in enumerate(zip(reference, effector)):
        r = without_stray_corners(r0, setup.reference.board, intrinsics, q_cfg)
        e = without_stray_corners(e0, setup.effector.board, intrinsics, q_cfg)
        why = judge_frame(r, "reference", setup, intrinsics, q_cfg) or judge_frame(
            e, "effector", setup, intrinsics, q_cfg
        )
        ref_pose = (
            None if why or r is None else solve_board_pose(r, setup.reference.board, intrinsics)
        )
        eff_pose = (
            None if why or e is None else solve_board_pose(e, setup.effector.board, intrinsics)
        )
        if ref_pose is None or eff_pose is None:
            skipped.append(why or "no pose")
            continue
        x = np.concatenate([ref_pose.rvec, ref_pose.tvec, eff_pose.rvec, eff_pose.tvec])
        positions[i] = compose(x, setup)
        jac = np.empty((3, 12))
        for j in range(12):
            h = 1e-6 if j % 6 < 3 else 1e-4
            step = np.zeros(12)
            step[j] = h
            jac[:, j] = (compose(x + step, setup) - compose(x - step, setup)) / (2 * h)
        cov = np.zeros((12, 12))
        cov[:6, :6] = ref_pose.covariance
        cov[6:, 6:] = eff_pose.covariance
        covariances[i] = jac @ cov @ jac.T
        skipped.append("")
    return FramePositions(positions, covariances, tuple(skipped))


def compose(x: np.ndarray, setup: CameraSetup) -> np.ndarray:
    """B in the base frame from (reference rvec, tvec, effector rvec, tvec), each board ->
    camera: camera -> reference board -> base, effector board -> camera, plus the offset."""
    r_ref, t_ref = rotvec_matrix(x[:3]), x[3:6]
    r_eff, t_eff = rotvec_matrix(x[6:9]), x[9:12]
    b_cam = r_eff @ np.asarray(setup.effector.offset, float) + t_eff
    in_ref = r_ref.T @ (b_cam - t_ref)
    ref = setup.reference
    return np.asarray(ref.rotation @ in_ref + np.asarray(ref.origin, float))
