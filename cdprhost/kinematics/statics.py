"""Cable tensions from the spring, gravity, an external force and acceleration.

Equilibrium (spec, paper eq. 7 with spring preload), u_k = (A_k - B)/|A_k - B|:
    sum_k T_k u_k + (F_s(z) - m g) e_z + W = m a
so T = U^-1 (m a - (F_s(z) - m g) e_z - W), U = [u_1 u_2 u_3].
Accelerations are in mm/s^2 (converted to m/s^2 for forces in N).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.profile.models import Statics


@dataclass(frozen=True)
class StaticsParams:
    k_s: float
    f0: float
    z_ref: float
    mass: float
    gravity: float
    external: np.ndarray
    t_min: float
    t_max: float
    a_max: float  # mm/s^2

    @classmethod
    def from_profile(cls, s: Statics) -> StaticsParams:
        return cls(
            s.spring_rate_n_per_mm,
            s.spring_preload_n,
            s.spring_ref_z_mm,
            s.effector_mass_kg,
            s.gravity_m_s2,
            np.asarray(s.external_force_n, float),
            s.tension_min_n,
            s.tension_max_n,
            s.a_max_mm_s2,
        )


def _inverse_rows(u: np.ndarray) -> np.ndarray:
    """Rows of U^-1 for U = [u_1 u_2 u_3] (columns), vectorised: (N, 3, 3)."""
    # the rows u2 x u3, u3 x u1, u1 x u2 in one call (three calls cost three times
    # np.cross's fixed overhead, which dominates at a calibration's few poses)
    rows = np.cross(u[:, [1, 2, 0], :], u[:, [2, 0, 1], :])
    det = np.einsum("ij,ij->i", u[:, 0, :], rows[:, 0, :])
    return np.asarray(rows / det[:, None, None])


def cable_units(points: np.ndarray, outlets: np.ndarray) -> np.ndarray:
    """u_k = (A_k - B)/|A_k - B|, shape (N, 3, 3) with [:, k, :] = u_k."""
    diff = outlets[None, :, :] - np.asarray(points, dtype=float)[:, None, :]
    return diff / np.linalg.norm(diff, axis=-1, keepdims=True)


def static_load(points: np.ndarray, sp: StaticsParams) -> np.ndarray:
    """-(F_s(z) - m g) e_z - W: the force the cables must supply at rest, (N, 3)."""
    z = np.asarray(points, dtype=float)[:, 2]
    spring = sp.f0 + sp.k_s * (sp.z_ref - z)
    load = np.zeros((z.shape[0], 3))
    load[:, 2] = -(spring - sp.mass * sp.gravity)
    return load - sp.external


def tensions(
    points: np.ndarray, outlets: np.ndarray, sp: StaticsParams, accel: np.ndarray | None = None
) -> np.ndarray:
    """Cable tensions T (N, 3) in N; ``accel`` (N, 3) in mm/s^2, default at rest."""
    rows = _inverse_rows(cable_units(points, outlets))
    rhs = static_load(points, sp)
    if accel is not None:
        rhs = rhs + sp.mass * 1e-3 * np.asarray(accel, dtype=float)
    return np.einsum("nkj,nj->nk", rows, rhs)


def tension_bounds(
    points: np.ndarray, outlets: np.ndarray, sp: StaticsParams
) -> tuple[np.ndarray, np.ndarray]:
    """Worst-case (lowest, highest) tension per cable over all |a| <= a_max: two (N, 3)."""
    rows = _inverse_rows(cable_units(points, outlets))
    t0 = np.einsum("nkj,nj->nk", rows, static_load(points, sp))
    swing = sp.mass * 1e-3 * sp.a_max * np.linalg.norm(rows, axis=-1)
    return t0 - swing, t0 + swing
