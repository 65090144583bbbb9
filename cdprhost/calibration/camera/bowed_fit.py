"""Intrinsics from views of a printed board that is not flat, and only the lens terms the
views observe.

Paper glued onto a board bows: a sheet whose middle stands 0.5 mm out of the plane of
its edges, fitted as flat, pulls the focal length down by a few tenths of a percent and
the principal point and tangential terms off by many of their own standard deviations.
:func:`refine_intrinsics` fits the board's shape with the lens: a quadratic height
``z = a u^2 + b v^2 + c u v`` over the chessboard (``u, v`` in half-widths and
half-heights from its middle; a constant or tilt is the view's pose), shared by every
view, jointly with the intrinsics and every view's pose (sparse least squares).

Which distortion terms are fitted is decided by the data: the tangential pair (p1, p2)
and k3 are held at zero unless freeing them lowers the corners' chi-square by more than
:data:`EVIDENCE` (a likelihood-ratio test) and they come out several of their own
standard deviations from zero; a term held at zero has std 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from cdprhost.calibration.camera.projection import project, rotvec_matrix

#: Chi-square drop (in units of the corner noise) a freed term group must buy.
EVIDENCE = 30.0
#: ... and how many of its own standard deviations it must stand from zero.
MIN_SIGNIFICANCE = 4.0
#: Indices of the groups of optional distortion terms in the 9-vector.
OPTIONAL_TERMS = {"tangential": (6, 7), "k3": (8,)}


@dataclass(frozen=True, eq=False)
class BowedFit:
    """``vector`` (9,) fx, fy, cx, cy, k1, k2, p1, p2, k3; ``std`` (9,) (0 for a term held
    at zero); ``bow`` (3,) a, b, c of the board's height (mm); ``bow_std`` (3,);
    ``rvecs``, ``tvecs`` (V, 3) per view; ``per_view_px`` RMS residual per view;
    ``rms_px``; ``sigma_px`` the corner noise; ``freed`` the optional term groups fitted;
    ``covariance`` (9, 9) of ``vector`` (zeros for held terms)."""

    vector: np.ndarray
    std: np.ndarray
    bow: np.ndarray
    bow_std: np.ndarray
    rvecs: np.ndarray
    tvecs: np.ndarray
    per_view_px: np.ndarray
    rms_px: float
    sigma_px: float
    freed: tuple[str, ...]
    covariance: np.ndarray

    @property
    def bow_mm(self) -> float:
        """The largest height of the fitted shape over the chessboard's corners' box (mm):
        at the middle against the edges and corners."""
        a, b, c = self.bow
        grid = np.array([[u, v] for u in (-1.0, 0.0, 1.0) for v in (-1.0, 0.0, 1.0)])
        z = a * grid[:, 0] ** 2 + b * grid[:, 1] ** 2 + c * grid[:, 0] * grid[:, 1]
        return float(np.ptp(z))


def board_uv(points: np.ndarray, all_corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Board positions over the box of ``all_corners``, in half-sizes from its middle."""
    lo, hi = all_corners[:, :2].min(axis=0), all_corners[:, :2].max(axis=0)
    mid, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, 1e-9)
    uv = (points[:, :2] - mid) / half
    return uv[:, 0], uv[:, 1]


def _fit(
    obj: list[np.ndarray],
    img: list[np.ndarray],
    v0: np.ndarray,
    rvecs: np.ndarray,
    tvecs: np.ndarray,
    bow0: np.ndarray,
    free: list[int],
    all_corners: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """One least-squares solve: returns v, bow, rvecs, tvecs, the parameters' covariance
    (the intrinsics in ``free`` then the bow), and the corner noise."""
    n_views = len(obj)
    counts = [len(o) for o in obj]
    pts = np.concatenate(obj)
    view = np.concatenate([np.full(n, i) for i, n in enumerate(counts)])
    uu, ww = board_uv(pts, all_corners)
    shape = np.stack([uu**2, ww**2, uu * ww], axis=1)
    observed = np.concatenate(img).ravel()
    n_i, n_b = len(free), 3

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        v = v0.copy()
        v[free] = x[:n_i]
        poses = x[n_i + n_b :].reshape(n_views, 6)
        return v, x[n_i : n_i + n_b], poses[:, :3], poses[:, 3:]

    def fun(x: np.ndarray) -> np.ndarray:
        v, bow, rv, tv = unpack(x)
        local = pts.copy()
        local[:, 2] = pts[:, 2] + shape @ bow
        rot = Rotation.from_rotvec(rv).as_matrix()[view]
        cam = np.einsum("nij,nj->ni", rot, local) + tv[view]
        return project(cam, v).ravel() - observed

    x0 = np.concatenate([v0[free], bow0, np.hstack([rvecs, tvecs]).ravel()])
    # dense Levenberg-Marquardt: a few hundred unknowns, a cheap model
    res = least_squares(fun, x0, method="lm", x_scale="jac", xtol=1e-10, ftol=1e-10)
    v, bow, rv, tv = unpack(res.x)
    dof = max(res.fun.size - res.x.size, 1)
    s2 = float(res.fun @ res.fun) / dof
    jac = res.jac.toarray() if hasattr(res.jac, "toarray") else np.asarray(res.jac)
    # the marginal covariance of the shared parameters (Schur complement of the poses)
    info = jac.T @ jac
    k = n_i + n_b
    a, b, d = info[:k, :k], info[:k, k:], info[k:, k:]
    d_inv = np.zeros_like(d)
    for i in range(n_views):
        blk = slice(6 * i, 6 * i + 6)
        d_inv[blk, blk] = np.linalg.pinv(d[blk, blk])
    cov = s2 * np.linalg.pinv(a - b @ d_inv @ b.T)
    return v, bow, rv, tv, cov, float(np.sqrt(s2))


def refine_intrinsics(
    obj: list[np.ndarray],
    img: list[np.ndarray],
    vector: np.ndarray,
    rvecs: np.ndarray,
    tvecs: np.ndarray,
    all_corners: np.ndarray,
    *,
    fit_k3: bool | None = None,
) -> BowedFit:
    """Intrinsics, board shape and view poses from board points ``obj`` (per view (n, 3),
    flat board frame, mm) seen at ``img`` (per view (n, 2) px), starting from ``vector``
    and the views' ``rvecs``, ``tvecs`` (e.g. OpenCV's flat fit). ``all_corners`` every
    corner of the board (its box normalises the shape). ``fit_k3`` True/False forces k3
    in or out; None lets the data decide (module doc)."""
    obj = [np.asarray(o, float).reshape(-1, 3) for o in obj]
    img = [np.asarray(i, float).reshape(-1, 2) for i in img]
    rv = np.asarray(rvecs, float).reshape(-1, 3)
    tv = np.asarray(tvecs, float).reshape(-1, 3)
    base = [0, 1, 2, 3, 4, 5]
    v0 = np.asarray(vector, float).copy()
    v0[6:9] = 0.0
    v, bow, rv, tv, cov, sigma = _fit(obj, img, v0, rv, tv, np.zeros(3), base, all_corners)
    free = list(base)
    n_points = sum(len(o) for o in obj)
    chi_now = sigma**2 * max(2 * n_points - len(free) - 3 - 6 * len(obj), 1)
    freed: list[str] = []
    for name, terms in OPTIONAL_TERMS.items():
        if name == "k3" and fit_k3 is False:
            continue
        trial_free = sorted(free + list(terms))
        t_v, t_bow, t_rv, t_tv, t_cov, t_sigma = _fit(
            obj, img, v, rv, tv, bow, trial_free, all_corners
        )
        dof = max(2 * n_points - len(trial_free) - 3 - 6 * len(obj), 1)
        chi_trial = t_sigma**2 * dof
        drop = (chi_now - chi_trial) / t_sigma**2
        pos = [trial_free.index(t) for t in terms]
        z = np.abs(t_v[list(terms)]) / np.sqrt(np.clip(np.diag(t_cov)[pos], 1e-30, None))
        forced = name == "k3" and fit_k3 is True
        if forced or (drop > EVIDENCE and float(z.max()) > MIN_SIGNIFICANCE):
            free, v, bow, rv, tv, cov, sigma = trial_free, t_v, t_bow, t_rv, t_tv, t_cov, t_sigma
            chi_now = chi_trial
            freed.append(name)
    std = np.zeros(9)
    std[free] = np.sqrt(np.clip(np.diag(cov)[: len(free)], 0.0, None))
    cov9 = np.zeros((9, 9))
    cov9[np.ix_(free, free)] = cov[: len(free), : len(free)]
    bow_std = np.sqrt(np.clip(np.diag(cov)[len(free) :], 0.0, None))
    per_view = []
    for o, i, r, t in zip(obj, img, rv, tv):
        u, w = board_uv(o, all_corners)
        local = o.copy()
        local[:, 2] = o[:, 2] + bow[0] * u**2 + bow[1] * w**2 + bow[2] * u * w
        pred = project(local @ rotvec_matrix(r).T + t, v)
        per_view.append(float(np.sqrt(np.mean(np.sum((pred - i) ** 2, axis=1)))))
    pv = np.array(per_view)
    counts = np.array([len(o) for o in obj], float)
    rms = float(np.sqrt(np.sum(pv**2 * counts) / counts.sum()))
    return BowedFit(v, std, bow, bow_std, rv, tv, pv, rms, sigma, tuple(freed), cov9)
