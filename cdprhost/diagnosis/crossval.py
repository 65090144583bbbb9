"""Held-out position error by pose (grouped K-fold) and the noise floor it should reach.

A pose is the unit left out: all three coordinates of a held-out pose come from
one take, so they leave together. Folds interleave the visiting order (pose i goes
to fold i mod K), so every fold spans the whole session in time, height and
approach direction.

Held-out error of a pose = 3D distance between its measured point and where the
model fitted without it says the effector went (forward kinematics with the pose's
time and approach directions).

Noise floor = the held-out RMS a *correct* model would show from noise alone:
E|e_i|^2 = sigma_i^2 (3 + tr(J_i C_f J_i^T)), with J the whitened Jacobian and
C_f = (J_T^T J_T)^-1 over the training rows of pose i's fold (a linearisation,
exact for a linear model).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cdprhost.calibration.fitting import CableModelFit, Observations, prediction_errors
from cdprhost.kinematics.machine import MachineModel


def pose_folds(n_poses: int, k: int) -> list[np.ndarray]:
    """Interleaved grouped folds over poses: fold j holds poses j, j+k, j+2k, ..."""
    k = max(2, min(int(k), n_poses))
    idx = np.arange(n_poses)
    return [idx[j::k] for j in range(k)]


def training_index(n_poses: int, test: np.ndarray) -> np.ndarray:
    mask = np.ones(n_poses, dtype=bool)
    mask[test] = False
    return np.flatnonzero(mask)


def heldout_errors(
    obs: Observations, start: MachineModel, effects: Sequence[str], folds: Sequence[np.ndarray]
) -> np.ndarray:
    """Per-pose held-out 3D error (mm) of the model 'geometry + ``effects``', shape (K,).

    ``start`` seeds every fold's fit (use the all-pose fit: folds then converge in a
    few iterations)."""
    n = len(obs)
    errors = np.full(n, np.nan)
    for test in folds:
        fit = CableModelFit(effects=tuple(effects)).fit(obs.subset(training_index(n, test)), start)
        errors[test] = prediction_errors(fit.model_, obs.subset(test))
    return errors


def rms(values: np.ndarray) -> float:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v * v))) if v.size else float("nan")


def expected_heldout_sq(
    jac: np.ndarray, sigma: np.ndarray | float, folds: Sequence[np.ndarray]
) -> np.ndarray:
    """Expected squared held-out error per pose for a correct model, shape (K,), mm^2.

    ``jac`` is the whitened Jacobian (3K, p) at the all-pose solution."""
    n = jac.shape[0] // 3
    sig = np.broadcast_to(np.asarray(sigma, dtype=float), (n,))
    blocks = jac.reshape(n, 3, -1)
    out = np.empty(n)
    for test in folds:
        train = blocks[training_index(n, test)].reshape(-1, jac.shape[1])
        cov = np.linalg.pinv(train.T @ train)
        jt = blocks[test]  # (m, 3, p)
        lev = np.einsum("mip,pq,miq->m", jt, cov, jt)
        out[test] = sig[test] ** 2 * (3.0 + lev)
    return out


def noise_floor_mm(
    jac: np.ndarray, sigma: np.ndarray | float, folds: Sequence[np.ndarray]
) -> float:
    """Held-out RMS (mm) expected from measurement noise alone for a correct model."""
    return float(np.sqrt(np.mean(expected_heldout_sq(jac, sigma, folds))))
