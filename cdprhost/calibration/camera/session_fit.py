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
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from cdprhost.calibration.camera.boards import CameraSetup, CharucoBoard
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.intrinsics import PARAMETER_NAMES, Intrinsics
from cdprhost.calibration.camera.pose import solve_board_pose
from cdprhost.calibration.camera.positions import FrameQuality, judge_frame
from cdprhost.calibration.camera.projection import project, rotvec_matrix
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.machine import MachineModel

#: Intrinsics the bundle adjustment may refine (indices into PARAMETER_NAMES).
REFINABLE = ("f", "cx", "cy", "k1", "k2")
#: Prior std of each refinable intrinsic when the calibration gives none, and the factor on
#: the calibration's own std (calibrateCamera's are optimistic: they see only corner noise).
PRIOR_FLOOR = {"f": 0.005, "cx": 8.0, "cy": 8.0, "k1": 0.03, "k2": 0.05}  # f: relative
PRIOR_FACTOR = 3.0
#: A refined intrinsic whose posterior std stays above this fraction of its prior is
#: "not observable from the motion".
OBSERVABLE_RATIO = 0.7
#: Floor of the corner noise (px) estimated from residuals.
MIN_PIXEL_SIGMA = 0.03
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
@dataclass(frozen=True)
class _Layout:
    """Parameter vector: [refined intrinsics..., camera rvec (3), tvec (3), board rotvec (3),
    then either q (12) or positions (3K)]."""

    refine: tuple[str, ...]
    n_tail: int

    @property
    def n_intr(self) -> int:
        return len(self.refine)

    def intrinsics(self, x: np.ndarray, base: np.ndarray) -> np.ndarray:
        v = base.copy()
        for i, name in enumerate(self.refine):
            if name == "f":
                v[0], v[1] = base[0] * x[i], base[1] * x[i]
            else:
                v[PARAMETER_NAMES.index(name)] = x[i]
        return v

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n = self.n_intr
        return x[n : n + 3], x[n + 3 : n + 6], x[n + 6 : n + 9], x[n + 9 :]


def _intr_start(refine: tuple[str, ...], v: np.ndarray) -> np.ndarray:
    return np.array([1.0 if n == "f" else v[PARAMETER_NAMES.index(n)] for n in refine])


def _intr_prior(refine: tuple[str, ...], intr: Intrinsics) -> np.ndarray:
    std = np.asarray(intr.std, float)
    v = intr.vector
    out = []
    for n in refine:
        if n == "f":
            rel = std[0] / v[0] if np.isfinite(std[0]) else 0.0
            out.append(max(PRIOR_FACTOR * rel, PRIOR_FLOOR["f"]))
        else:
            s = std[PARAMETER_NAMES.index(n)]
            out.append(max(PRIOR_FACTOR * s if np.isfinite(s) else 0.0, PRIOR_FLOOR[n]))
    return np.array(out)


def _camera_points(points_base: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    return np.asarray(points_base @ rotvec_matrix(rvec).T + tvec)


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
        f0 = project(_camera_points(local + c, rvec, tvec), v)
        h = 1e-3
        jac = np.stack(
            [
                (project(_camera_points(local + c + h * e, rvec, tvec), v) - f0).ravel() / h
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
    (default :data:`REFINABLE`) jointly with the 12 parameters; without them, the
    camera-only positions. ``fit_rows`` (K,) bool: the poses that enter the bundle
    adjustment (default all; check poses are left out so that they test it). Raises ValueError when the reference board is never seen well
    enough (naming the frames) or no pose has a usable frame."""
    q_cfg = quality or FrameQuality()
    ref_board, eff_board = setup.reference.board, setup.effector.board
    v0 = intrinsics.vector
    k_poses = len(takes)
    # 1. frames
    skipped: list[tuple[str, ...]] = []
    for take in takes:
        reasons = []
        for r, e in zip(take.reference, take.effector):
            why = judge_frame(r, "reference", setup, intrinsics, q_cfg)
            why = why or judge_frame(e, "effector", setup, intrinsics, q_cfg)
            reasons.append(why)
        skipped.append(tuple(reasons))
    good = [[i for i, s in enumerate(sk) if not s] for sk in skipped]
    ref_dets = [
        d for take, g in zip(takes, good) for i in g if (d := take.reference[i]) is not None
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
    stage3 = _fit_camera_only(
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
        ba = _bundle_adjust(
            ref_obj,
            ref_px,
            eff_means,
            ba_idx,
            board_pts,
            offset,
            intrinsics,
            refine if refine is not None else REFINABLE,
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
    frame_pos = []
    for kk, take in enumerate(takes):
        fp = np.full((len(take.effector), 3), np.nan)
        for i in good[kk]:
            d = take.effector[i]
            if d is None or not np.isfinite(origins[kk]).all():
                continue
            c, _ = _solve_position(
                d.corners_px, board_pts[d.ids], rot_eff, v, cam_r, cam_t, origins[kk], 3
            )
            fp[i] = c + rot_eff @ offset
        frame_pos.append(fp)
    # the vector shared by every B: board orientation error x offset, offset as printed
    lever = _skew(rot_eff @ offset)
    off_sigma = setup.effector.offset_sigma_mm or DEFAULT_OFFSET_SIGMA_MM
    common = lever @ cov_eff_rot @ lever.T + off_sigma**2 * np.eye(3)
    frame = frame_covariance(
        cam_r, cam_t, camera_pose_covariance(ref_ids, ref_obj, ref_px, ref_board, v, cam_r, cam_t)
    )
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
    )


def camera_pose_covariance(
    ids: np.ndarray,
    obj: np.ndarray,
    px: np.ndarray,
    board: CharucoBoard,
    v: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
) -> np.ndarray:
    """Covariance (6, 6) of the camera pose (rvec, tvec) from the reference board's corners:
    block jackknifes over the board's columns and over its rows of corners, added (the
    errors of neighbouring corners are alike: lens model, detector bias, printing, so the
    formal covariance of independent corners is too small), or the formal one from the
    residuals, whichever is larger."""
    k = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1]])
    dist = v[4:9]
    xy = board.corners_mm[ids, :2]
    x0 = np.concatenate([rvec, tvec])
    proj, jac = cv2.projectPoints(obj, rvec, tvec, k, dist)
    resid = proj.reshape(-1, 2) - px
    dof = max(resid.size - 6, 1)
    s2 = max(float(np.sum(resid**2)) / dof, MIN_PIXEL_SIGMA**2)
    j = np.asarray(jac, float)[:, :6]
    formal = s2 * np.linalg.pinv(j.T @ j)
    jacks = []
    for axis in (0, 1):  # delete one column of corners at a time, then one row
        est = []
        for value in np.unique(xy[:, axis]):
            keep = xy[:, axis] != value
            if keep.sum() < 6:
                continue
            r, t = cv2.solvePnPRefineLM(obj[keep], px[keep], k, dist, rvec.copy(), tvec.copy())
            est.append(np.concatenate([np.ravel(r), np.ravel(t)]) - x0)
        g = len(est)
        if g >= 3:
            dev = np.array(est) - np.mean(est, axis=0)
            jacks.append((g - 1) / g * (dev.T @ dev))
    if not jacks:
        return formal
    # deleting rows sees errors that differ from row to row, deleting columns those that
    # differ from column to column; a pattern may do both, so the two parts add
    jack = np.sum(jacks, axis=0)
    return jack if np.trace(jack[3:, 3:]) > np.trace(formal[3:, 3:]) else formal


def frame_covariance(rvec: np.ndarray, tvec: np.ndarray, camera_cov: np.ndarray) -> np.ndarray:
    """The camera pose's covariance as a rigid error of the base frame: dB = w x B + t
    for every measured B, (6, 6) of (w, t)."""
    r = rotvec_matrix(rvec)
    probe = np.array([[0, 0, 150.0], [150, 0, 150], [0, 150, 150], [0, 0, 300], [-150, -100, 250]])
    cam_pts = probe @ r.T + tvec

    def to_base(x: np.ndarray) -> np.ndarray:
        rr = rotvec_matrix(x[:3])
        return np.asarray((cam_pts - x[3:]) @ rr)

    x0 = np.concatenate([rvec, tvec])
    design = np.concatenate([np.hstack([-_skew(p), np.eye(3)]) for p in probe])
    mapping = np.empty((6, 6))
    for j in range(6):
        h = 1e-6 if j < 3 else 1e-3
        step = np.zeros(6)
        step[j] = h
        d_b = (to_base(x0 + step) - to_base(x0 - step)).ravel() / (2 * h)
        mapping[:, j] = np.linalg.lstsq(design, d_b, rcond=None)[0]
    return np.asarray(mapping @ camera_cov @ mapping.T)


def _skew(a: np.ndarray) -> np.ndarray:
    """[a]x such that [a]x b = a x b; a small rotation w moves R p by w x (R p) = -[Rp]x w."""
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


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
        pred = project(_camera_points(board_pts[ids] @ rot_eff.T + origins[k], cam_r, cam_t), v)
        ss += float(np.sum((pred - px) ** 2))
        n += 2 * len(ids) - 3
    return max(float(np.sqrt(ss / max(n, 1))), MIN_PIXEL_SIGMA)


def _fit_camera_only(
    ref_obj: np.ndarray,
    ref_px: np.ndarray,
    eff_means: list[tuple[np.ndarray, np.ndarray] | None],
    idx: np.ndarray,
    board_pts: np.ndarray,
    v: np.ndarray,
    cam_r: np.ndarray,
    cam_t: np.ndarray,
    eff_rv: np.ndarray,
    origins: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Camera pose, one board orientation and a free origin per pose, from every corner;
    and the covariance of the orientation (rad^2)."""
    means = [eff_means[k] for k in idx]

    eff_local = np.concatenate([board_pts[m[0]] for m in means if m is not None])
    eff_pose = np.concatenate([np.full(len(m[0]), i) for i, m in enumerate(means) if m is not None])
    observed = np.concatenate([ref_px.ravel()] + [m[1].ravel() for m in means if m is not None])

    def fun(x: np.ndarray) -> np.ndarray:
        cr, ct, er = x[:3], x[3:6], x[6:9]
        cs = x[9:].reshape(-1, 3)
        pts = np.concatenate([ref_obj, eff_local @ rotvec_matrix(er).T + cs[eff_pose]])
        return project(_camera_points(pts, cr, ct), v).ravel() - observed

    x0 = np.concatenate([cam_r, cam_t, eff_rv, origins[idx].ravel()])
    sparsity = _sparsity(len(ref_px), [len(m[0]) for m in means if m is not None])
    res = least_squares(fun, x0, jac_sparsity=sparsity, method="trf", x_scale="jac", xtol=1e-12)
    x = res.x
    jac = res.jac.toarray() if hasattr(res.jac, "toarray") else np.asarray(res.jac)
    dof = max(res.fun.size - x.size, 1)
    s2 = max(float(res.fun @ res.fun) / dof, MIN_PIXEL_SIGMA**2)
    cov_er = s2 * np.linalg.pinv(jac.T @ jac)[6:9, 6:9]
    return x[:3], x[3:6], x[6:9], x[9:].reshape(-1, 3), cov_er


def _sparsity(n_ref: int, n_eff: list[int]) -> lil_matrix:
    """Jacobian pattern of the camera-only fit: the reference corners depend on the camera
    pose; a pose's effector corners on it, the board orientation and that pose's origin."""
    s = lil_matrix((2 * (n_ref + sum(n_eff)), 9 + 3 * len(n_eff)), dtype=int)
    s[: 2 * n_ref, :6] = 1
    r = 2 * n_ref
    for k, n in enumerate(n_eff):
        s[r : r + 2 * n, :9] = 1
        s[r : r + 2 * n, 9 + 3 * k : 12 + 3 * k] = 1
        r += 2 * n
    return s


def _bundle_adjust(
    ref_obj: np.ndarray,
    ref_px: np.ndarray,
    eff_means: list[tuple[np.ndarray, np.ndarray] | None],
    idx: np.ndarray,
    board_pts: np.ndarray,
    offset: np.ndarray,
    intrinsics: Intrinsics,
    refine: tuple[str, ...],
    cam_r: np.ndarray,
    cam_t: np.ndarray,
    eff_rv: np.ndarray,
    sliders: np.ndarray,
    model: MachineModel,
    origins: np.ndarray,
) -> tuple[
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    np.ndarray,
    float,
    tuple[str, ...],
    list[str],
    np.ndarray,
    np.ndarray,
]:
    """Stage 4 (module doc). Returns intrinsics vector, camera rvec, tvec, board rotvec,
    q, corner sigma (px), the intrinsics refined, notes, the (12, 12) covariance the camera
    parameters add to q, and the (3, 3) covariance of the board orientation (rad^2)."""
    from cdprhost.calibration.fitting import Observations
    from cdprhost.calibration.identification import identify

    v0 = intrinsics.vector
    means = [eff_means[k] for k in idx]
    # a start for q: the geometry identified from the camera-only positions
    rot = rotvec_matrix(eff_rv)
    start_pos = origins + rot @ offset
    first = identify(Observations(start_pos, sliders, sigma_mm=0.1), model)
    q0 = first.geometry.q if np.all(np.isfinite(first.geometry.q)) else model.geometry.q
    layout = _Layout(tuple(refine), 12)
    prior = _intr_prior(layout.refine, intrinsics)
    x_intr0 = _intr_start(layout.refine, v0)

    # every effector corner of every pose at once: board points and their pose's row
    eff_local = np.concatenate([board_pts[m[0]] - offset for m in means if m is not None])
    eff_pose = np.concatenate([np.full(len(m[0]), i) for i, m in enumerate(means) if m is not None])

    def predict(x: np.ndarray) -> np.ndarray:
        v = layout.intrinsics(x, v0)
        cr, ct, er, q = layout.split(x)
        b = model.with_geometry(CableGeometry.from_q(q), model.effects).fk(sliders)
        pts = np.concatenate([ref_obj, eff_local @ rotvec_matrix(er).T + b[eff_pose]])
        return project(_camera_points(pts, cr, ct), v).ravel()

    observed = np.concatenate([ref_px.ravel()] + [m[1].ravel() for m in means if m is not None])

    def fun(x: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        r = (predict(x) - observed) / sigma
        pri = (x[: layout.n_intr] - x_intr0) / prior
        return np.concatenate([r, pri])

    x0 = np.concatenate([x_intr0, cam_r, cam_t, eff_rv, q0])
    # the reference board's corners and the effector board's have their own noise (a large
    # board seen obliquely, a small one face-on): each estimated from its own residuals
    n_ref = ref_px.size
    is_ref = np.arange(observed.size) < n_ref
    sig_ref = sig_eff = 0.1
    res = None
    used = np.where(is_ref, sig_ref, sig_eff)
    for _ in range(2):  # solve, estimate the corner noise from the residuals, solve again
        used = np.where(is_ref, sig_ref, sig_eff)
        res = least_squares(
            fun, x0, args=(used,), method="lm", x_scale="jac", xtol=1e-10, ftol=1e-12
        )
        pix = res.fun[: observed.size] * used
        dof_ref = max(n_ref - 6, 1)
        dof_eff = max(observed.size - n_ref - (x0.size - layout.n_intr - 6), 1)
        sig_ref = max(float(np.sqrt(np.sum(pix[is_ref] ** 2) / dof_ref)), MIN_PIXEL_SIGMA)
        sig_eff = max(float(np.sqrt(np.sum(pix[~is_ref] ** 2) / dof_eff)), MIN_PIXEL_SIGMA)
        x0 = res.x
    sigma = sig_eff
    assert res is not None
    jac = np.array(res.jac.toarray() if hasattr(res.jac, "toarray") else res.jac, dtype=float)
    # the last solve weighed the corners by the previous sigmas
    jac[: observed.size] *= (used / np.where(is_ref, sig_ref, sig_eff))[:, None]
    info = jac.T @ jac
    cov = np.linalg.pinv(info)
    x = res.x
    n_i = layout.n_intr
    post = np.sqrt(np.clip(np.diag(cov)[:n_i], 0, None))
    notes: list[str] = []
    refined = []
    for name, p, s in zip(layout.refine, prior, post):
        if s > OBSERVABLE_RATIO * p:
            notes.append(
                f"intrinsic {name} not observable from the robot's motion (std {s:.3g} of a prior "
                f"{p:.3g}): kept near its calibration"
            )
        else:
            refined.append(name)
    # what the camera parameters' uncertainty adds to q: full marginal minus q given them
    q_sl = slice(n_i + 9, n_i + 21)
    cov_q_full = cov[q_sl, q_sl]
    cov_q_given = np.linalg.pinv(info[q_sl, q_sl])
    extra = cov_q_full - cov_q_given
    w, vec = np.linalg.eigh(0.5 * (extra + extra.T))
    extra = (vec * np.clip(w, 0, None)) @ vec.T
    er_sl = slice(n_i + 6, n_i + 9)
    v = layout.intrinsics(x, v0)
    cr, ct, er, q = layout.split(x)
    return v, cr, ct, er, q, sigma, tuple(refined), notes, extra, cov[er_sl, er_sl]
