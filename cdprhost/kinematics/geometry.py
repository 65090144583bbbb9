"""Ideal cable geometry: straight cables from three outlets to one point.

IK: L_k = |B - A_k|, s_k = L_k - L_k0. FK: the intersection of three spheres in
closed form, taking the root above the outlets. Everything is vectorised over N
points; outlets are a (3, 3) array whose row k is A_k.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CableGeometry:
    """The 12 kinematic parameters in the spec's order."""

    outlets: np.ndarray  # (3, 3), row k = A_k
    initial_lengths: np.ndarray  # (3,), L_k0

    @classmethod
    def from_q(cls, q: np.ndarray) -> CableGeometry:
        q = np.asarray(q, dtype=float)
        return cls(q[:9].reshape(3, 3).copy(), q[9:12].copy())

    @property
    def q(self) -> np.ndarray:
        return np.concatenate([self.outlets.ravel(), self.initial_lengths])


def cable_lengths(points: np.ndarray, outlets: np.ndarray) -> np.ndarray:
    """|B - A_k| for every point, shape (N, 3)."""
    p = np.asarray(points, dtype=float)
    x, y, z = p[..., 0:1], p[..., 1:2], p[..., 2:3]
    dx = x - outlets[:, 0]
    dy = y - outlets[:, 1]
    dz = z - outlets[:, 2]
    return np.sqrt(dx * dx + dy * dy + dz * dz)


def sliders_from_lengths(lengths: np.ndarray, geometry: CableGeometry) -> np.ndarray:
    return lengths - geometry.initial_lengths


def ik_sliders(points: np.ndarray, geometry: CableGeometry) -> np.ndarray:
    """Ideal slider displacements s_k = |B - A_k| - L_k0, shape (N, 3)."""
    return cable_lengths(points, geometry.outlets) - geometry.initial_lengths


@dataclass(frozen=True)
class _TrilaterationFrame:
    origin: np.ndarray
    basis: np.ndarray  # rows ex, ey, ez (ez points to the side above the outlets)
    d: float
    i: float
    j: float


def _frame(outlets: np.ndarray) -> _TrilaterationFrame:
    a1, a2, a3 = outlets
    ex = a2 - a1
    d = float(np.linalg.norm(ex))
    ex = ex / d
    i = float(ex @ (a3 - a1))
    ey = a3 - a1 - i * ex
    j = float(np.linalg.norm(ey))
    ey = ey / j
    ez = np.cross(ex, ey)
    if ez[2] < 0:  # the wanted root lies above the outlets (+z in the base frame)
        ez = -ez
        ey = -ey
        j = -j
    return _TrilaterationFrame(a1, np.stack([ex, ey, ez]), d, i, j)


def fk_from_lengths(lengths: np.ndarray, outlets: np.ndarray) -> np.ndarray:
    """Closed-form three-sphere intersection, root above the outlets. (N, 3) -> (N, 3).

    Lengths with no real intersection give NaN rows.
    """
    f = _frame(np.asarray(outlets, dtype=float))
    r = np.asarray(lengths, dtype=float)
    r1s, r2s, r3s = r[..., 0] ** 2, r[..., 1] ** 2, r[..., 2] ** 2
    x = (r1s - r2s + f.d * f.d) / (2.0 * f.d)
    y = (r1s - r3s + f.i * f.i + f.j * f.j) / (2.0 * f.j) - (f.i / f.j) * x
    zz = r1s - x * x - y * y
    with np.errstate(invalid="ignore"):
        z = np.sqrt(np.where(zz >= 0, zz, np.nan))
    local = np.stack([x, y, z], axis=-1)
    return f.origin + local @ f.basis


def fk_points(sliders: np.ndarray, geometry: CableGeometry) -> np.ndarray:
    """Ideal FK: slider displacements (N, 3) -> effector points (N, 3)."""
    return fk_from_lengths(
        np.asarray(sliders, dtype=float) + geometry.initial_lengths, geometry.outlets
    )
