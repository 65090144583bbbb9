"""Jacobians: joint rates from Cartesian rates, and the identification Jacobian J0.

Velocity Jacobian: ds_k/dB = (B - A_k)^T / L_k, i.e. row k is the unit vector from
outlet k to the effector.

Identification Jacobian (paper eq. 4-6). Differentiating |B - A_k|^2 = (L_k0 + s_k)^2
at fixed s_k gives (B - A_k) . dB = (B - A_k) . dA_k + L_k dL_k0, i.e.
``C dB = D^T dq`` with C's row k = (B - A_k)^T and D^T's row k holding (B - A_k)^T
in A_k's three slots and L_k in L_k0's slot. So dB = J0 dq, J0 = C^-1 D^T.
"""

from __future__ import annotations

import numpy as np

from cdprhost.kinematics.geometry import CableGeometry


def velocity_jacobian(points: np.ndarray, outlets: np.ndarray) -> np.ndarray:
    """ds/dB at every point: (N, 3, 3), row k = (B - A_k) / |B - A_k|."""
    diff = np.asarray(points, dtype=float)[..., None, :] - outlets[None, :, :]
    return diff / np.linalg.norm(diff, axis=-1, keepdims=True)


def length_jacobian_q(points: np.ndarray, geometry: CableGeometry) -> tuple[np.ndarray, np.ndarray]:
    """C (N, 3, 3) and D^T (N, 3, 12) of the paper's eq. 4."""
    p = np.asarray(points, dtype=float)
    n = p.shape[0]
    diff = p[:, None, :] - geometry.outlets[None, :, :]  # (N, 3, 3): row k = B - A_k
    lengths = np.linalg.norm(diff, axis=-1)
    dt = np.zeros((n, 3, 12))
    for k in range(3):  # three fixed columns blocks, not a per-point loop
        dt[:, k, 3 * k : 3 * k + 3] = diff[:, k, :]
        dt[:, k, 9 + k] = lengths[:, k]
    return diff, dt


def identification_jacobian(points: np.ndarray, geometry: CableGeometry) -> np.ndarray:
    """J0 = C^-1 D^T stacked over poses: (3N, 12); dB = J0 dq at each pose."""
    c, dt = length_jacobian_q(points, geometry)
    j0 = np.linalg.solve(c, dt)  # (N, 3, 12)
    return j0.reshape(-1, 12)


def residual_jacobian(points: np.ndarray, geometry: CableGeometry) -> np.ndarray:
    """d r / d q for cable-length residuals r_k = |B - A_k| - L_k0 - s_k: (3N, 12).

    Block-sparse: cable k's residual depends only on (A_k, L_k0).
    """
    p = np.asarray(points, dtype=float)
    diff = p[:, None, :] - geometry.outlets[None, :, :]
    unit = diff / np.linalg.norm(diff, axis=-1, keepdims=True)
    jac = np.zeros((p.shape[0], 3, 12))
    for k in range(3):
        jac[:, k, 3 * k : 3 * k + 3] = -unit[:, k, :]
        jac[:, k, 9 + k] = -1.0
    return jac.reshape(-1, 12)
