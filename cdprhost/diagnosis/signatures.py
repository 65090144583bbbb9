"""Effect signatures: what each effect does to the whitened residuals, and what the
geometry can already do.

An effect's *signature* is the Jacobian of the whitened residuals with respect to
its parameters, taken at the fitted base model with the effect switched off. If the
signature lies in the span of the 12 geometric columns, refitting the geometry
reproduces the effect exactly: it is *absorbed* and can never be named. Two
effects whose signatures, with the geometry projected out, share a direction are
*confusable* on this set of poses.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.fitting import CableModelFit, Observations, whitened_residuals
from cdprhost.effects.base import Effect
from cdprhost.effects.registry import EffectChain
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.machine import MachineModel

GEOMETRY_STEP_MM = 1e-5


def numeric_jacobian(
    fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, steps: np.ndarray
) -> np.ndarray:
    """Central-difference Jacobian, one column per parameter (each call vectorised over poses)."""
    x = np.asarray(x, dtype=float)
    cols = []
    for i, h in enumerate(steps):
        e = np.zeros_like(x)
        e[i] = h
        cols.append((fun(x + e) - fun(x - e)) / (2.0 * h))
    return np.column_stack(cols) if cols else np.zeros((fun(x).size, 0))


def parameter_steps(x: np.ndarray, n_geometry: int) -> np.ndarray:
    x = np.abs(np.asarray(x, dtype=float))
    steps = np.maximum(1e-4 * x, 1e-7)
    steps[:n_geometry] = GEOMETRY_STEP_MM
    return steps


def fit_jacobian(fit: CableModelFit, obs: Observations) -> np.ndarray:
    """Jacobian (3K, p) of the whitened residuals at a fitted estimator's solution."""
    base = fit.base_

    def fun(x: np.ndarray) -> np.ndarray:
        return whitened_residuals(fit.model_at(base, x), obs).ravel()

    return numeric_jacobian(fun, fit.x_, parameter_steps(fit.x_, 12 if fit.fit_geometry else 0))


def effect_signature(
    model: MachineModel, obs: Observations, effect: Effect
) -> tuple[np.ndarray, np.ndarray]:
    """(G, S): whitened-residual Jacobians for the 12 geometric parameters and for ``effect``'s
    parameters, at ``model`` with the effect added at its null vector. Works for any Effect,
    registered in the catalogue or not."""
    chain = model.effects
    keep = [(e, v) for e, v in zip(chain.effects, chain.vectors) if e.name != effect.name]
    null = effect.null_vector()
    q0 = model.geometry.q

    def fun(x: np.ndarray) -> np.ndarray:
        c = EffectChain(
            tuple(e for e, _ in keep) + (effect,), tuple(v for _, v in keep) + (x[12:],)
        )
        return whitened_residuals(model.with_geometry(CableGeometry.from_q(x[:12]), c), obs).ravel()

    x0 = np.concatenate([q0, null])
    jac = numeric_jacobian(fun, x0, parameter_steps(x0, 12))
    return jac[:, :12], jac[:, 12:]


def orthonormal_span(mat: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """Orthonormal basis of the column space of ``mat`` (columns scaled to unit norm first)."""
    norms = np.linalg.norm(mat, axis=0)
    cols = mat[:, norms > 0] / norms[norms > 0]
    if cols.shape[1] == 0:
        return np.zeros((mat.shape[0], 0))
    u, sv, _ = np.linalg.svd(cols, full_matrices=False)
    return u[:, sv > rtol * sv[0]]


def project_out(basis: np.ndarray, mat: np.ndarray) -> np.ndarray:
    return np.asarray(mat - basis @ (basis.T @ mat))


@dataclass(frozen=True)
class SignatureReport:
    """Per effect: how much of its signature the geometry cannot reproduce (0 = fully
    absorbed, 1 = orthogonal to the geometry), worst and best direction."""

    name: str
    unabsorbed_min: float
    unabsorbed_max: float
    absorbed: bool
    partly_absorbed: bool
    residual_basis: np.ndarray  # orthonormal basis of the signature with the geometry projected out


def analyse_signature(
    name: str,
    geometry_jac: np.ndarray,
    signature: np.ndarray,
    absorbed_below: float = 1e-3,
    partly_below: float = 0.1,
) -> SignatureReport:
    basis = orthonormal_span(geometry_jac)
    norms = np.linalg.norm(signature, axis=0)
    unit = signature / np.where(norms > 0, norms, 1.0)
    rest = project_out(basis, unit)
    u, sv, _ = np.linalg.svd(rest, full_matrices=False)
    lo, hi = (float(sv.min()), float(sv.max())) if sv.size else (0.0, 0.0)
    return SignatureReport(
        name, lo, hi, hi < absorbed_below, lo < partly_below, u[:, sv > absorbed_below]
    )


def principal_correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Cosine of the smallest principal angle between two orthonormal column spaces."""
    if a.shape[1] == 0 or b.shape[1] == 0:
        return 0.0
    return float(np.clip(np.linalg.svd(a.T @ b, compute_uv=False).max(), 0.0, 1.0))


def confusable_pairs(
    reports: Sequence[SignatureReport], threshold: float = 0.9
) -> list[tuple[str, str, float]]:
    """Pairs of effects whose geometry-free signatures share a direction (|cos| >= threshold)."""
    out = []
    for i, a in enumerate(reports):
        for b in reports[i + 1 :]:
            c = principal_correlation(a.residual_basis, b.residual_basis)
            if c >= threshold:
                out.append((a.name, b.name, c))
    return out


def pair_correlations(reports: Sequence[SignatureReport]) -> dict[tuple[str, str], float]:
    return {
        (a.name, b.name): principal_correlation(a.residual_basis, b.residual_basis)
        for i, a in enumerate(reports)
        for b in reports[i + 1 :]
    }
