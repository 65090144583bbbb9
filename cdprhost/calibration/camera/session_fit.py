"""The session-level fit: one camera pose, one effector-board orientation and (where the
data make them observable) refined intrinsics, jointly with the 12 geometric parameters,
from the corners of every frame, with the robot's commanded motion as constraint.

The camera does not move during a session and the effector only translates, so one camera
pose and one board orientation fit every frame. A frame's corner errors are mostly the same
in every frame of a take (the scene is static: detector bias, lens model), so each take's
frames are first averaged corner by corner (the reference board, which never moves, over
the whole session) and the corner noise is estimated from what the fits leave.

Stages:

1. frames judged (corners, sharpness, reprojection error of each board's own PnP);
2. the camera pose from every reference-board corner of the session;
3. one effector-board orientation with a free position per pose (no kinematics): the
   camera-only positions;
4. with the commanded sliders and a model: bundle adjustment of the intrinsics (focal
   length, principal point, k1, k2 under a prior from their calibration), the camera pose,
   the board orientation and the 12 parameters, the board at ``B_k = FK(q, s_k)``; an
   intrinsic the motion does not pin down (posterior std > 0.7 x prior) is said so;
5. every pose's and frame's B re-solved (3 unknowns) with that camera.

Each pose's covariance is its corners' noise carried through the 3-unknown solution
(anisotropic: depth is worst); the camera parameters' uncertainty is the same for every
pose, so it is returned as what it does to the 12 parameters (``geometry_covariance_extra``)
and, for the board orientation and the offset as printed, as the one vector it adds to
every B (``common_covariance``), which no identification can see.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from cdprhost.calibration.camera.boards import CameraSetup
from cdprhost.calibration.camera.bundle_adjustment import (
    bundle_adjust,
    camera_points,
    fit_camera_only,
)
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.intrinsics import PARAMETER_NAMES, Intrinsics
from cdprhost.calibration.camera.pose import solve_board_pose
from cdprhost.calibration.camera.pose_covariance import (
    MIN_PIXEL_SIGMA,
    camera_pose_covariance,
    frame_covariance,
    skew,
)
from cdprhost.calibration.camera.positions import (
    FrameQuality,
    judge_frame,
    without_stray_corners,
)
from cdprhost.calibration.camera.projection import project, rotvec_matrix
from cdprhost.kinematics.machine import MachineModel

#: Intrinsics the bundle adjustment may refine (indices into PARAMETER_NAMES).
REFINABLE = ("f", "cx", "cy", "k1", "k2")
#: ... and those it refines only when the calibration fitted them (a term the calibration
#: views did not observe is held at zero, std 0).
REFINABLE_WHEN_FITTED = ("p1", "p2", "k3")


def default_refine(intrinsics: Intrinsics) -> tuple[str, ...]:
    """:data:`REFINABLE` and the terms of :data:`REFINABLE_WHEN_FITTED` the calibration
    fitted (a finite, non-zero std)."""
    std = np.asarray(intrinsics.std, float)
    fitted = tuple(
        n
        for n in REFINABLE_WHEN_FITTED
        if np.isfinite(s := std[PARAMETER_NAMES.index(n)]) and s > 0
    )
    return REFINABLE + fitted


#: Std of the effector board's offset per coordinate (mm) when the set-up states none.
DEFAULT_OFFSET_SIGMA_MM = 0.0


@dataclass(frozen=True, eq=False)
class TakeDetections:
    """The detections of one take (one pose): per frame, each board's or None."""

    reference: tuple[BoardDetection | None, ...]
    effector: tuple[BoardDetection | None, ...]
    times_s: np.ndarray | None = None  # (F,) frame times; default 0, 1/30, ...

    def __post_init__(self) -> None:
        if len(self.reference) != len(self.effector):
            raise ValueError(
                f"{len(self.reference)} reference and {len(self.effector)} effector frames"
            )

    @property
    def times(self) -> np.ndarray:
        n = len(self.reference)
        return np.arange(n) / 30.0 if self.times_s is None else np.asarray(self.times_s, float)


@dataclass(frozen=True, eq=False)
class SessionFit:
    """What the session-level fit found (see the module doc).

    ``frame_positions`` per pose (F, 3) B of every frame (NaN when skipped);
    ``frame_skipped`` per pose, per frame '' or the reason (naming the board);
    ``positions`` (K, 3) each pose's B from its averaged corners (NaN: no usable frame);
    ``covariances`` (K, 3, 3) their corner-noise covariance; ``common_covariance`` (3, 3);
    ``geometry_covariance_extra`` (12, 12) what the camera parameters' uncertainty adds to
    the 12 parameters (zeros without the bundle adjustment); ``intrinsics`` (refined);
    ``camera_rvec``, ``camera_tvec`` base -> camera; ``effector_rotation`` board -> base;
    ``pixel_sigma`` the corner noise (px); ``refined`` the intrinsics refined and observable;
    ``notes``; ``geometry_q`` the bundle adjustment's 12 parameters (or None)."""

    frame_positions: tuple[np.ndarray, ...]
    frame_skipped: tuple[tuple[str, ...], ...]
    positions: np.ndarray
    covariances: np.ndarray
    common_covariance: np.ndarray
    geometry_covariance_extra: np.ndarray
    intrinsics: Intrinsics
    camera_rvec: np.ndarray
    camera_tvec: np.ndarray
    effector_rotation: np.ndarray
    pixel_sigma: float
    refined: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    geometry_q: np.ndarray | None = None
    # (6, 6) of the rigid error (rotation vector about the base origin, rad; translation,
    # mm) with which the reference board's pose puts every B in a slightly wrong frame
    frame_covariance: np.ndarray = field(default_factory=lambda: np.zeros((6, 6)))
    extra: dict[str, float] = field(default_factory=dict)
    # (K, 3, 3) the covariance of one frame's B about its take's mean: the frame-to-frame
    # corner noise (``frame_pixel_sigma``, px, pooled over the session's ordinary takes) through the pose's
    # solution; what a take's drift test measures its frames against (NaN: no position)
    frame_noise_covariances: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    frame_pixel_sigma: float = float("nan")

    @property
    def usable(self) -> np.ndarray:
        """(K,) poses with a position."""
        return np.asarray(np.isfinite(self.positions).all(axis=1))


def _mean_corners(
    dets: list[BoardDetection], n_ids: int, min_fraction: float = 0.5
) -> tuple[np.ndarray, np.ndarray]:
    """Corner ids seen in at least ``min_fraction`` of ``dets`` and their mean pixels."""
    total = np.zeros((n_ids, 2))
    count = np.zeros(n_ids)
    for d in dets:
        np.add.at(total, d.ids, d.corners_px)
        np.add.at(count, d.ids, 1.0)
    ids = np.flatnonzero(count >= max(1.0, min_fraction * len(dets)))
    return ids, total[ids] / count[ids, None]


# ----------------------------------------------------------------- the camera model


def _solve_position(
    px: np.ndarray,
    board_pts: np.ndarray,
    rot_eff: np.ndarray,
    v: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    start: np.ndarray,
    iterations: int = 6,
) -> tuple[np.ndarray, np.ndarray]:
    """Board origin c (base frame) from one set of effector corners (3 unknowns,
    Gauss-Newton) and the Jacobian of their pixels by c, (2n, 3)."""
    c = np.asarray(start, float).copy()
    local = board_pts @ rot_eff.T
    jac = np.zeros((2 * len(px), 3))
    for _ in range(iterations):
        f0 = project(camera_points(local + c, rvec, tvec), v)
        h = 1e-3
        jac = np.stack(
            [
                (project(camera_points(local + c + h * e, rvec, tvec), v) - f0).ravel() / h
                for e in np.eye(3)
            ],
            axis=1,
        )
        r = (px - f0).ravel()
        step = np.linalg.lstsq(jac, r, rcond=None)[0]
        c = c + step
        if np.max(np.abs(step)) < 1e-6:
            break
    return c, jac


# ----------------------------------------------------------------- the fit
def fit_session(
    takes: list[TakeDetections],
    setup: CameraSetup,
    intrinsics: Intrinsics,
    sliders: np.ndarray | None = None,
    model: MachineModel | None = None,
    *,
    refine: tuple[str, ...] | None = None,
    quality: FrameQuality | None = None,
    fit_rows: np.ndarray | None = None,
) -> SessionFit:
    """The session-level fit (module doc). With ``sliders`` (K, 3) commanded and ``model``
    (the profile's), the bundle adjustment refines the intrinsics named in ``refine``
    (default :func:`default_refine`) jointly with the 12 parameters; without them, the
    camera-only positions. ``fit_rows`` (K,) bool: the poses that enter the bundle
    adjustment (default all; check poses are left out so that they test it). Raises ValueError when the reference board is never seen well
    enough (naming the frames) or no pose has a usable frame."""
    q_cfg = quality or FrameQuality()
    ref_board, eff_board = setup.reference.board, setup.effector.board
    v0 = intrinsics.vector
    k_poses = len(takes)
    # 1. frames. A frame whose reference board is seen whole and well gives its corners to
    # the session's camera pose; a frame whose reference board is only good less a few stray
    # corners (the effector in front of it) still gives its effector board, but not those
    # corners: the ones beside the hiding edge that stay under the stray limit would pull
    # the base frame (measured: a worse workspace RMS, and a gate that under-predicts)
    whole: list[tuple[bool, ...]] = []
    skipped: list[tuple[str, ...]] = []
    for take in takes:
        reasons, seen_whole = [], []
        for raw, e in zip(take.reference, take.effector):
            ref = without_stray_corners(raw, ref_board, intrinsics, q_cfg)
            why = judge_frame(ref, "reference", setup, intrinsics, q_cfg)
            seen_whole.append(
                why == ""
                if ref is raw
                else judge_frame(raw, "reference", setup, intrinsics, q_cfg) == ""
            )
            reasons.append(why or judge_frame(e, "effector", setup, intrinsics, q_cfg))
        skipped.append(tuple(reasons))
        whole.append(tuple(seen_whole))
    good = [[i for i, s in enumerate(sk) if not s] for sk in skipped]
    ref_dets = [
        d
        for take, g, w in zip(takes, good, whole)
        for i in g
        if w[i] and (d := take.reference[i]) is not None
    ]
    if not ref_dets:
        raise ValueError(
            "the reference board is not seen well enough in any frame: "
            + "; ".join(
                f"pose {k + 1}: {sk[0] if sk else 'no frames'}" for k, sk in enumerate(skipped[:8])
            )
        )
    ref_ids, ref_px = _mean_corners(ref_dets, len(ref_board.corners_mm))
    ref_obj = setup.reference.corners_base[ref_ids]
    # 2. camera pose (base -> camera) from the session's reference corners
    k_mat = np.asarray(intrinsics.matrix, float)
    _ok, rvec, tvec = cv2.solvePnP(ref_obj, ref_px, k_mat, intrinsics.distortion_5)
    rvec, tvec = cv2.solvePnPRefineLM(ref_obj, ref_px, k_mat, intrinsics.distortion_5, rvec, tvec)
    cam_r, cam_t = np.asarray(rvec, float).ravel(), np.asarray(tvec, float).ravel()
    # 3. effector board: one orientation, a free origin per pose
    eff_means: list[tuple[np.ndarray, np.ndarray] | None] = []
    rotations = []
    for take, g in zip(takes, good):
        dets = [d for i in g if (d := take.effector[i]) is not None]
        if not dets:
            eff_means.append(None)
            continue
        eff_means.append(_mean_corners(dets, len(eff_board.corners_mm)))
        for d in dets[:3]:
            pose = solve_board_pose(d, eff_board, intrinsics)
            if pose is not None:
                rotations.append(rotvec_matrix(cam_r).T @ pose.rotation)
    usable = np.array([m is not None for m in eff_means])
    if not usable.any():
        raise ValueError("the effector board is not seen well enough in any frame of any pose")
    rot0 = Rotation.from_matrix(np.array(rotations)).mean()
    board_pts = eff_board.corners_mm
    starts = []
    for m in eff_means:
        if m is None:
            starts.append(np.full(3, np.nan))
            continue
        ids, px = m
        pose_c = _rough_origin(px, board_pts[ids], rot0.as_matrix(), v0, cam_r, cam_t)
        starts.append(pose_c)
    origins = np.array(starts)
    idx = np.flatnonzero(usable)
    stage3 = fit_camera_only(
        ref_obj, ref_px, eff_means, idx, board_pts, v0, cam_r, cam_t, rot0.as_rotvec(), origins
    )
    cam_r, cam_t, eff_rv, origins[idx], cov_eff_rot = stage3
    v = v0
    notes: list[str] = []
    refined: tuple[str, ...] = ()
    q_fit = None
    extra_q = np.zeros((12, 12))
    sigma_px = float("nan")
    offset = np.asarray(setup.effector.offset, float)
    ba_idx = idx if fit_rows is None else idx[np.asarray(fit_rows, bool)[idx]]
    if sliders is not None and model is not None and ba_idx.size >= 4:
        ba = bundle_adjust(
            ref_obj,
            ref_px,
            eff_means,
            ba_idx,
            board_pts,
            offset,
            intrinsics,
            refine if refine is not None else default_refine(intrinsics),
            cam_r,
            cam_t,
            eff_rv,
            np.asarray(sliders, float)[ba_idx],
            model,
            origins[ba_idx],
        )
        v, cam_r, cam_t, eff_rv, q_fit, sigma_px, refined, notes, extra_q, cov_eff_rot = ba
    rot_eff = rotvec_matrix(eff_rv)
    # 5. positions of every pose and frame with that camera
    positions = np.full((k_poses, 3), np.nan)
    jacs: list[np.ndarray | None] = [None] * k_poses
    for k in idx:
        m = eff_means[k]
        assert m is not None
        ids, px = m
        c, jac = _solve_position(px, board_pts[ids], rot_eff, v, cam_r, cam_t, origins[k])
        positions[k] = c + rot_eff @ offset
        jacs[k] = jac
        origins[k] = c
    if not np.isfinite(sigma_px):
        sigma_px = _pixel_sigma(eff_means, idx, board_pts, rot_eff, v, cam_r, cam_t, origins)
    covariances = np.full((k_poses, 3, 3), np.nan)
    for k in idx:
        j = jacs[k]
        assert j is not None
        covariances[k] = sigma_px**2 * np.linalg.inv(j.T @ j)
    frame_sigma = _frame_pixel_sigma(takes, good, eff_means)
    frame_noise = np.full((k_poses, 3, 3), np.nan)
    frame_pos = []
    for kk, take in enumerate(takes):
        fp = np.full((len(take.effector), 3), np.nan)
        frame_pos.append(fp)
        if not np.isfinite(origins[kk]).all():
            continue
        seen = {i: d for i in good[kk] if (d := take.effector[i]) is not None}
        shared = _shared_corners(list(seen.values()))
        frame_jac: np.ndarray | None = jacs[kk]
        for i, d in seen.items():
            sel = np.isin(d.ids, shared) if shared is not None else np.ones(len(d.ids), bool)
            c, solved_jac = _solve_position(
                d.corners_px[sel], board_pts[d.ids[sel]], rot_eff, v, cam_r, cam_t, origins[kk], 3
            )
            fp[i] = c + rot_eff @ offset
            if shared is not None:
                frame_jac = solved_jac
        if frame_jac is not None:
            frame_noise[kk] = frame_sigma**2 * np.linalg.inv(frame_jac.T @ frame_jac)
    # the vector shared by every B: board orientation error x offset, offset as printed
    lever = skew(rot_eff @ offset)
    off_sigma = setup.effector.offset_sigma_mm or DEFAULT_OFFSET_SIGMA_MM
    common = off_sigma**2 * np.eye(3)
    frame = np.zeros((6, 6))
    if q_fit is None:
        common = common + lever @ cov_eff_rot @ lever.T
        frame = frame_covariance(
            cam_r,
            cam_t,
            camera_pose_covariance(ref_ids, ref_obj, ref_px, ref_board, v, cam_r, cam_t),
        )
    # else: the bundle adjustment estimated the camera pose and the board orientation with
    # the 12 parameters; what their uncertainty does to the workspace is already in
    # ``geometry_covariance_extra`` (a rigid frame error or a constant shift of every B is
    # a direction of the parameters): adding it again counted it twice
    v_std = np.asarray(intrinsics.std, float).copy()
    out_intr = Intrinsics.from_vector(
        v, intrinsics.image_size, v_std, intrinsics.rms_reprojection_px
    )
    for lost in np.flatnonzero(~usable):
        sk = skipped[lost]
        notes.append(f"pose {lost + 1}: no usable frame ({sk[0] if sk else 'no frames'})")
    return SessionFit(
        tuple(frame_pos),
        tuple(skipped),
        positions,
        covariances,
        common,
        extra_q,
        out_intr,
        cam_r,
        cam_t,
        rot_eff,
        float(sigma_px),
        refined,
        tuple(notes),
        q_fit,
        frame,
        frame_noise_covariances=frame_noise,
        frame_pixel_sigma=frame_sigma,
    )


#: A take whose corners scatter (variance) more than this many times the session's median
#: take is not pooled into the frame noise (a shaking or creeping effector).
FRAME_NOISE_OUTLIER = 10.0
#: The fewest corners shared by a take's frames that its frames are compared on.
MIN_SHARED_CORNERS = 6


def _shared_corners(dets: list[BoardDetection]) -> np.ndarray | None:
    """The effector corners every frame of a take found, when they pin a position (at
    least :data:`MIN_SHARED_CORNERS`); else None (each frame then uses all it found).

    The frames of a take are compared with each other (drift, scatter) on these alone: a
    corner's error has a part that stays the same for the whole take (the picture at that
    place), which cancels between frames that use the same corners but not between a frame
    that lost a marker and one that kept it (a 0.5 mm jump along the line of sight, several
    times the frame-to-frame noise, from three corners fewer)."""
    if not dets:
        return None
    shared = dets[0].ids
    for d in dets[1:]:
        shared = np.intersect1d(shared, d.ids)
    return shared if len(shared) >= MIN_SHARED_CORNERS else None


def _frame_pixel_sigma(
    takes: list[TakeDetections],
    good: list[list[int]],
    eff_means: list[tuple[np.ndarray, np.ndarray] | None],
) -> float:
    """The effector corners' frame-to-frame noise (px per coordinate), pooled over the
    session: each usable frame's corners about their take's mean (n frames leave n - 1
    degrees of freedom per corner coordinate). With at least three takes, a take whose own
    variance is over :data:`FRAME_NOISE_OUTLIER` times the takes' median is left out: its
    effector shook or crept, and must not inflate the noise every take (its own included)
    is judged against."""
    ss, dof = 0.0, 0.0
    per_take: list[tuple[float, float]] = []
    for take, g, m in zip(takes, good, eff_means):
        if m is None:
            continue
        ids, mean_px = m
        lookup = {int(i): row for row, i in enumerate(ids)}
        dets = [d for i in g if (d := take.effector[i]) is not None]
        counts = np.zeros(len(ids))
        sq = np.zeros(len(ids))
        for d in dets:
            rows = np.array([lookup.get(int(i), -1) for i in d.ids])
            sel = rows >= 0
            diff = d.corners_px[sel] - mean_px[rows[sel]]
            np.add.at(sq, rows[sel], np.sum(diff**2, axis=1))
            np.add.at(counts, rows[sel], 1.0)
        seen = counts >= 2
        take_ss = float(np.sum(sq[seen]))
        take_dof = float(np.sum(2.0 * (counts[seen] - 1.0)))
        ss += take_ss
        dof += take_dof
        if take_dof >= 1:
            per_take.append((take_ss, take_dof))
    if dof < 1:
        return float("nan")
    if len(per_take) >= 3:
        t_ss, t_dof = np.array(per_take).T
        keep = t_ss / t_dof <= FRAME_NOISE_OUTLIER * float(np.median(t_ss / t_dof))
        ss, dof = float(np.sum(t_ss[keep])), float(np.sum(t_dof[keep]))
    return max(float(np.sqrt(ss / dof)), MIN_PIXEL_SIGMA / 10)


def _rough_origin(
    px: np.ndarray,
    board_pts: np.ndarray,
    rot_eff: np.ndarray,
    v: np.ndarray,
    cam_r: np.ndarray,
    cam_t: np.ndarray,
) -> np.ndarray:
    """A start for a pose's board origin: PnP of its averaged corners, into the base."""
    k = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1]])
    _ok, _rvec, tvec = cv2.solvePnP(board_pts, px, k, v[4:9], flags=cv2.SOLVEPNP_IPPE)
    r_cam = rotvec_matrix(cam_r)
    return np.asarray(r_cam.T @ (np.asarray(tvec, float).ravel() - cam_t))


def _pixel_sigma(
    eff_means: list[tuple[np.ndarray, np.ndarray] | None],
    idx: np.ndarray,
    board_pts: np.ndarray,
    rot_eff: np.ndarray,
    v: np.ndarray,
    cam_r: np.ndarray,
    cam_t: np.ndarray,
    origins: np.ndarray,
) -> float:
    ss, n = 0.0, 0
    for k in idx:
        m = eff_means[k]
        assert m is not None
        ids, px = m
        pred = project(camera_points(board_pts[ids] @ rot_eff.T + origins[k], cam_r, cam_t), v)
        ss += float(np.sum((pred - px) ** 2))
        n += 2 * len(ids) - 3
    return max(float(np.sqrt(ss / max(n, 1))), MIN_PIXEL_SIGMA)
