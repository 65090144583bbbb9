"""Nonlinear least squares of the cable model to measured poses (estimator core).

Shared by identification (the 12 geometric parameters) and diagnosis (the 12 plus
catalogue effects). Observations are measured effector points B_i with the slider
displacements commanded there. The residual of cable k at pose i is
``r_ik = |B_i - A_k| - stretch(L_k0 + s_act_ik)`` (``MachineModel.length_residuals``).

Noise model: motion capture errs in the *position* of B (sigma per coordinate),
and that one error enters all three cables of a pose, so a pose's residuals are
correlated with covariance sigma^2 J J^T (J's rows are the unit cable vectors).
Whitening by (sigma J)^-1 gives independent unit-variance residuals, which are
also the position-space misfit divided by sigma.

Follows scikit-learn's shape: configure a :class:`CableModelFit`, ``fit`` it on
:class:`Observations`, then read fitted attributes or ``predict`` positions.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from cdprhost.effects.base import MotionContext
from cdprhost.effects.registry import CATALOGUE, EffectChain
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.jacobian import velocity_jacobian
from cdprhost.kinematics.machine import MachineModel

GEOMETRY_NAMES = (
    "x_1a",
    "y_1a",
    "z_1a",
    "x_2a",
    "y_2a",
    "z_2a",
    "x_3a",
    "y_3a",
    "z_3a",
    "L_10",
    "L_20",
    "L_30",
)


@dataclass(frozen=True)
class Observations:
    """K measured poses. ``sigma_mm`` is the mocap noise per coordinate (scalar or (K,))."""

    measured: np.ndarray  # (K, 3) base frame, mm
    sliders: np.ndarray  # (K, 3) commanded slider displacements, mm
    t_s: np.ndarray | None = None  # (K,)
    directions: np.ndarray | None = None  # (K, 3)
    sigma_mm: float | np.ndarray = 0.05
    # (K, 3, 3) full noise covariance of each pose (mm^2), e.g. a camera's, whose depth is
    # worse than its lateral precision; when given it whitens the residuals instead of sigma
    covariance: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.measured.shape[0])

    @property
    def context(self) -> MotionContext:
        return MotionContext(t_s=self.t_s, directions=self.directions)

    def subset(self, index: np.ndarray) -> Observations:
        sig = self.sigma_mm if np.ndim(self.sigma_mm) == 0 else np.asarray(self.sigma_mm)[index]
        return Observations(
            self.measured[index],
            self.sliders[index],
            None if self.t_s is None else self.t_s[index],
            None if self.directions is None else self.directions[index],
            sig,
            None if self.covariance is None else np.asarray(self.covariance)[index],
        )

    def with_sigma(self, sigma_mm: float | np.ndarray) -> Observations:
        """The same poses with another per-coordinate noise (a full covariance is widened by
        the same factor per pose)."""
        cov = self.covariance
        if cov is not None:
            old = np.sqrt(np.trace(cov, axis1=1, axis2=2) / 3.0)
            new = np.broadcast_to(np.asarray(sigma_mm, float), old.shape)
            extra = np.clip(new**2 - old**2, 0.0, None)
            cov = cov + extra[:, None, None] * np.eye(3)
        return Observations(self.measured, self.sliders, self.t_s, self.directions, sigma_mm, cov)


def sigma_from_covariance(covariance: np.ndarray) -> np.ndarray:
    """Per-coordinate sigma of each pose, sqrt(trace / 3), (K,)."""
    return np.asarray(np.sqrt(np.trace(covariance, axis1=1, axis2=2) / 3.0))


def position_misfit(model: MachineModel, obs: Observations) -> np.ndarray:
    """Linearised position-space misfit J^-1 r at every pose, (K, 3) in mm."""
    r = model.length_residuals(obs.measured, obs.sliders, obs.context)
    jac = velocity_jacobian(obs.measured, model.geometry.outlets)
    return np.linalg.solve(jac, r[..., None])[..., 0]


def whitened_residuals(model: MachineModel, obs: Observations) -> np.ndarray:
    """The position misfit whitened by each pose's noise: divided by sigma, or with a full
    covariance C = L L^T, L^-1 misfit (independent unit-variance residuals either way)."""
    misfit = position_misfit(model, obs)
    if obs.covariance is not None:
        chol = np.linalg.cholesky(np.asarray(obs.covariance, dtype=float))
        return np.asarray(np.linalg.solve(chol, misfit[..., None])[..., 0])
    sig = np.asarray(obs.sigma_mm, dtype=float)
    return np.asarray(misfit / (sig if sig.ndim == 0 else sig[:, None]))


def prediction_errors(model: MachineModel, obs: Observations) -> np.ndarray:
    """3D distance between measured points and where ``model`` says the effector went (K,)."""
    predicted = model.fk(obs.sliders, obs.context)
    return np.asarray(np.linalg.norm(predicted - obs.measured, axis=1))


@dataclass
class CableModelFit:
    """Estimator of the 12 geometric parameters and (optionally) catalogue effects.

    Parameters: ``effects`` names catalogue effects to fit alongside the geometry;
    ``fit_geometry=False`` holds the 12 parameters at the base model's values.
    Fitted attributes (after ``fit``): ``model_``, ``names_``, ``x_``, ``stderr_``,
    ``covariance_``, ``correlation_``, ``chi2_``, ``dof_``, ``iterations_`` (accepted
    parameter updates), ``iterates_`` (x0 then each accepted iterate), ``nfev_``,
    ``converged_``, ``residuals_`` (whitened, (K, 3)), ``information_`` (J^T J of
    the whitened residuals), ``singular_values_`` (of the
    column-scaled Jacobian), ``null_space_`` (right singular vectors of the
    unidentifiable directions).
    """

    effects: Sequence[str] = ()
    fit_geometry: bool = True
    scale_covariance: bool = True
    xtol: float = 1e-12
    ftol: float = 1e-12
    max_nfev: int = 200
    identifiable_ratio: float = 1e-7
    names_: tuple[str, ...] = field(init=False, default=())

    def _layout(self, base: MachineModel) -> tuple[tuple[str, ...], np.ndarray, list[int]]:
        names: list[str] = list(GEOMETRY_NAMES) if self.fit_geometry else []
        x0: list[np.ndarray] = [base.geometry.q] if self.fit_geometry else []
        sizes = []
        start_vectors = dict(zip(base.effects.names, base.effects.vectors))
        for name in self.effects:
            effect = CATALOGUE[name]
            names += [f"{name}.{v}" for v in effect.vector_names]
            x0.append(start_vectors.get(name, effect.null_vector()))
            sizes.append(len(effect.vector_names))
        return tuple(names), (np.concatenate(x0) if x0 else np.zeros(0)), sizes

    def model_at(self, base: MachineModel, x: np.ndarray) -> MachineModel:
        geometry = CableGeometry.from_q(x[:12]) if self.fit_geometry else base.geometry
        offset = 12 if self.fit_geometry else 0
        vectors = []
        for name in self.effects:
            n = len(CATALOGUE[name].vector_names)
            vectors.append(x[offset : offset + n])
            offset += n
        fixed = [
            (n, v)
            for n, v in zip(base.effects.names, base.effects.vectors)
            if n not in self.effects
        ]
        names = [n for n, _ in fixed] + list(self.effects)
        chain = EffectChain.from_vectors(names, [v for _, v in fixed] + vectors)
        return base.with_geometry(geometry, chain)

    def fit(self, obs: Observations, base: MachineModel) -> CableModelFit:
        names, x0, _ = self._layout(base)
        self.names_ = names
        self.base_ = base

        def fun(x: np.ndarray) -> np.ndarray:
            return whitened_residuals(self.model_at(base, x), obs).ravel()

        iterates: list[np.ndarray] = []

        def jac(x: np.ndarray) -> np.ndarray:
            # The solver evaluates the Jacobian once per accepted parameter update,
            # so the points it is evaluated at are the iterates.
            if not iterates or not np.array_equal(iterates[-1], x):
                iterates.append(np.array(x, dtype=float))
            return self._jacobian(base, x, fun)

        result = least_squares(
            fun,
            x0,
            jac=jac,
            method="lm" if len(obs) * 3 >= len(x0) else "trf",
            x_scale="jac",
            xtol=self.xtol,
            ftol=self.ftol,
            gtol=1e-15,
            max_nfev=self.max_nfev * max(1, len(x0)),
        )
        self.x_ = result.x
        self.model_ = self.model_at(base, result.x)
        self.residuals_ = result.fun.reshape(-1, 3)
        self.chi2_ = float(result.fun @ result.fun)
        self.n_obs_ = result.fun.size
        self.dof_ = max(self.n_obs_ - len(x0), 0)
        self.converged_ = bool(result.status > 0)
        if not np.array_equal(iterates[-1], result.x):
            iterates.append(np.array(result.x, dtype=float))
        self.iterates_ = np.array(iterates)
        self.iterations_ = len(iterates) - 1
        self.nfev_ = int(result.nfev)
        self._covariance(self._jacobian(base, result.x, fun))
        return self

    def _jacobian(
        self, base: MachineModel, x: np.ndarray, fun: Callable[[np.ndarray], np.ndarray]
    ) -> np.ndarray:
        """Central-difference Jacobian at the solution (more accurate than the solver's)."""
        f0 = fun(x)
        jac = np.empty((f0.size, x.size))
        for i in range(
            x.size
        ):  # one column per parameter; each evaluation is vectorised over poses
            h = (
                1e-6 * max(1.0, abs(x[i]))
                if i < 12 or not self.effects
                else max(1e-9, 1e-4 * abs(x[i]) + 1e-9)
            )
            e = np.zeros_like(x)
            e[i] = h
            jac[:, i] = (fun(x + e) - fun(x - e)) / (2 * h)
        return jac

    def _covariance(self, jac: np.ndarray) -> None:
        self.information_ = jac.T @ jac
        norms = np.linalg.norm(jac, axis=0)
        norms[norms == 0] = 1.0
        scaled = jac / norms
        _, sv, vt = np.linalg.svd(scaled, full_matrices=False)
        self.singular_values_ = sv
        weak = sv < self.identifiable_ratio * sv[0] if sv.size else np.zeros(0, bool)
        self.null_space_ = vt[weak]
        inv_sv2 = np.where(weak, 0.0, 1.0 / np.where(sv > 0, sv, 1.0) ** 2)
        cov_scaled = (vt.T * inv_sv2) @ vt
        cov = cov_scaled / np.outer(norms, norms)
        if self.scale_covariance and self.dof_ > 0:
            cov = cov * max(self.chi2_ / self.dof_, 1e-300)
        self.covariance_ = cov
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        sd[
            np.isin(
                np.arange(sd.size),
                np.flatnonzero(np.abs(self.null_space_).max(axis=0) > 0.1) if weak.any() else [],
            )
        ] = np.inf
        self.stderr_ = sd
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(sd, sd)
        self.correlation_ = np.where(np.isfinite(corr), corr, 0.0)

    def updates_until(self, step_tol: float) -> int:
        """Parameter updates until one changes no parameter by more than ``step_tol``
        (the paper's stopping rule, section 5.2); ``iterations_`` + 1 if none did."""
        steps = (
            np.abs(np.diff(self.iterates_, axis=0)).max(axis=1)
            if len(self.iterates_) > 1
            else np.zeros(1)
        )
        small = np.flatnonzero(steps <= step_tol)
        return int(small[0] + 1) if small.size else self.iterations_ + 1

    # ------------------------------------------------------------- reporting
    def predict(self, sliders: np.ndarray, ctx: MotionContext | None = None) -> np.ndarray:
        return self.model_.fk(sliders, ctx)

    def effect_vector(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        idx = [i for i, n in enumerate(self.names_) if n.startswith(name + ".")]
        return self.x_[idx], self.stderr_[idx]

    def high_correlations(self, threshold: float = 0.95) -> list[tuple[str, str, float]]:
        c = self.correlation_
        i, j = np.triu_indices_from(c, k=1)
        keep = np.abs(c[i, j]) > threshold
        return [(self.names_[a], self.names_[b], float(c[a, b])) for a, b in zip(i[keep], j[keep])]

    def unidentifiable(self, top: int = 4) -> list[str]:
        """Each weak direction as a readable combination of its largest components."""
        out = []
        for vec in self.null_space_:
            order = np.argsort(-np.abs(vec))[:top]
            terms = [f"{vec[i]:+.2f}*{self.names_[i]}" for i in order if abs(vec[i]) > 0.05]
            out.append(" ".join(terms))
        return out
