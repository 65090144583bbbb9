"""Least-squares rigid fit (Kabsch) between point sets, vectorised over frames.

Registration maps motion-capture coordinates into the base frame: each frame's
base markers (mocap frame) are fitted to their known base-frame positions, and
the fitted transform then carries every other marker of that frame across.
Gaps (NaN) simply drop out of a frame's fit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.mocap.readers.take import Take

# Relative size of the second singular value below which points count as collinear.
COLLINEAR_TOL = 1e-9


@dataclass(frozen=True, eq=False)
class RigidTransform:
    """``x_dst = R @ x_src + t``. Batched: R (..., 3, 3), t (..., 3), residuals (...).

    ``rms_residual`` is the (weighted) RMS distance of the fitted points after the
    transform; ``n_points`` how many points entered each fit. A fit that was
    impossible (fewer than 3 points, or collinear) has NaN in R, t and the residual.
    """

    R: np.ndarray
    t: np.ndarray
    rms_residual: np.ndarray
    n_points: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        return np.asarray(np.isfinite(self.rms_residual))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform points (..., m, 3); the batch dims broadcast against the transform's."""
        p = np.asarray(points, dtype=float)
        return np.asarray(np.einsum("...ij,...mj->...mi", self.R, p) + self.t[..., None, :])

    def inverse(self) -> RigidTransform:
        rt = np.swapaxes(self.R, -1, -2)
        return RigidTransform(
            rt, -np.einsum("...ij,...j->...i", rt, self.t), self.rms_residual, self.n_points
        )


def kabsch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> RigidTransform:
    """Rigid transform (proper rotation, no scale) minimising sum w |R src + t - dst|^2.

    ``src`` and ``dst`` are (..., n, 3) and broadcast against each other; ``weights``
    (..., n) default 1. Points with NaN in either set get weight 0.
    """
    s = np.asarray(src, dtype=float)
    d = np.asarray(dst, dtype=float)
    s, d = np.broadcast_arrays(s, d)
    w = (
        np.ones(s.shape[:-1])
        if weights is None
        else np.broadcast_to(np.asarray(weights, dtype=float), s.shape[:-1])
    )
    gap = np.isnan(s).any(axis=-1) | np.isnan(d).any(axis=-1)
    w = np.where(gap, 0.0, w)
    s = np.where(gap[..., None], 0.0, s)
    d = np.where(gap[..., None], 0.0, d)
    wsum = w.sum(axis=-1)
    safe = np.where(wsum > 0, wsum, 1.0)
    mu_s = np.einsum("...n,...ni->...i", w, s) / safe[..., None]
    mu_d = np.einsum("...n,...ni->...i", w, d) / safe[..., None]
    sc = s - mu_s[..., None, :]
    dc = d - mu_d[..., None, :]
    h = np.einsum("...n,...ni,...nj->...ij", w, sc, dc)
    u, sing, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, -1, -2)
    sign = np.sign(np.linalg.det(v @ np.swapaxes(u, -1, -2)))
    sign = np.where(sign == 0, 1.0, sign)
    fix = np.ones(sign.shape + (3,))
    fix[..., 2] = sign
    rot = (v * fix[..., None, :]) @ np.swapaxes(u, -1, -2)
    t = mu_d - np.einsum("...ij,...j->...i", rot, mu_s)
    fitted = np.einsum("...ij,...nj->...ni", rot, s) + t[..., None, :]
    sq = np.einsum("...n,...n->...", w, np.sum((fitted - d) ** 2, axis=-1))
    rms = np.sqrt(sq / safe)
    n_points = np.count_nonzero(w > 0, axis=-1)
    bad = (n_points < 3) | ~(sing[..., 1] > COLLINEAR_TOL * sing[..., 0])
    rot = np.where(bad[..., None, None], np.nan, rot)
    t = np.where(bad[..., None], np.nan, t)
    rms = np.where(bad, np.nan, rms)
    return RigidTransform(rot, t, rms, n_points)


def is_degenerate(points: np.ndarray) -> bool:
    """True if fewer than 3 points or all on one line (a rigid fit would be ambiguous)."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(p) < 3:
        return True
    sing = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    return not sing[1] > 1e-6 * max(sing[0], 1.0)


def register_frames(take: Take, base_markers: Mapping[str, Sequence[float]]) -> RigidTransform:
    """Per-frame transform mocap -> base frame from the base markers (batch over frames)."""
    names = list(base_markers)
    measured = take.select(names)  # (frames, n, 3)
    nominal = np.asarray([base_markers[n] for n in names], dtype=float)  # (n, 3)
    return kabsch(measured, nominal[None, :, :])


def rotation_about_z(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
