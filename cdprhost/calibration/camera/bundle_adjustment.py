"""The least-squares fits inside a camera session's fit: the camera pose, one board
orientation and a free origin per pose from every corner (the camera-only fit), and the
bundle adjustment that refines intrinsics, camera pose, board orientation and the 12
kinematic parameters (or free positions) together, with priors on the intrinsics."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from cdprhost.calibration.camera.intrinsics import PARAMETER_NAMES, Intrinsics
from cdprhost.calibration.camera.pose_covariance import (
    MIN_PIXEL_SIGMA,
)
from cdprhost.calibration.camera.projection import project, rotvec_matrix
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.machine import MachineModel

#: Prior std of each refinable intrinsic when the calibration gives none, and the factor on
#: the calibration's own std (calibrateCamera's are optimistic: they see only corner noise).
PRIOR_FLOOR = {
    "f": 0.005,  # relative
    "cx": 8.0,
    "cy": 8.0,
    "k1": 0.03,
    "k2": 0.05,
    "p1": 0.0005,
    "p2": 0.0005,
    "k3": 0.05,
}


PRIOR_FACTOR = 3.0


#: A refined intrinsic whose posterior std stays above this fraction of its prior is
#: "not observable from the motion".
OBSERVABLE_RATIO = 0.7


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


def camera_points(points_base: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    return np.asarray(points_base @ rotvec_matrix(rvec).T + tvec)


def fit_camera_only(
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
        return project(camera_points(pts, cr, ct), v).ravel() - observed

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


def bundle_adjust(
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
        return project(camera_points(pts, cr, ct), v).ravel()

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
