"""Identification of the 12 geometric parameters from measured poses, and whether to trust it.

A thin layer over :class:`~cdprhost.calibration.fitting.CableModelFit` (the one
estimator): it fits the poses marked ``fit``, predicts the ``check`` poses, and gathers
what a user needs to trust the result: standard errors and 95 % intervals, high
correlations, scaled singular values with the unidentifiable combinations named,
per-pose errors, RMS before and after, and the trust gate of :mod:`.trust` (the
parameter covariance carried to the build volume). The profile's own effects are held at
their values while the geometry is fitted.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import ValidationError
from scipy import stats

from cdprhost.calibration.fitting import GEOMETRY_NAMES, CableModelFit, Observations
from cdprhost.calibration.pose_noise import PoseNoise
from cdprhost.calibration.trust import (
    DEFAULT_TRUST,
    TrustLimits,
    TrustReport,
    trust_report,
    variance_factor,
)
from cdprhost.calibration.verification import DEFAULT_ALPHA, Verification, verify_checks
from cdprhost.errors import JobFailed
from cdprhost.jsonsafe import json_safe
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.grid import workspace_grid
from cdprhost.kinematics.jacobian import identification_jacobian
from cdprhost.kinematics.machine import MachineModel
from cdprhost.profile.models import MachineProfile

MIN_POSES = 4


@dataclass(frozen=True)
class Identification:
    """Result of one identification. Errors are 3D distances (mm) between the
    measured point and where a model says the commanded sliders put the effector."""

    nominal: CableGeometry
    geometry: CableGeometry
    stderr: np.ndarray  # (12,)
    ci95: np.ndarray  # (12, 2)
    correlations: list[tuple[str, str, float]]
    singular_values: np.ndarray
    unidentifiable: list[str]
    roles: tuple[str, ...]  # per pose: "fit" | "check"
    errors_before: np.ndarray  # (K,)
    errors_after: np.ndarray  # (K,)
    residuals_after: np.ndarray  # (K, 3) predicted - measured, mm
    iterations: int
    converged: bool
    chi2: float
    dof: int
    sigma_mm: np.ndarray  # (K,)
    model: MachineModel = field(repr=False)
    rejected: tuple[str, ...] = ()
    trust: TrustReport | None = None
    covariance: np.ndarray | None = field(default=None, repr=False)  # (12, 12), scaled
    pose_numbers: np.ndarray | None = None  # (K,) poses.csv numbers
    noise: PoseNoise | None = None
    notes: tuple[str, ...] = ()
    verification: Verification | None = None

    names = GEOMETRY_NAMES

    @property
    def fit_mask(self) -> np.ndarray:
        return np.asarray(np.array(self.roles) == "fit")

    @property
    def poses_used(self) -> int:
        return int(self.fit_mask.sum())

    def _rms(self, errors: np.ndarray, mask: np.ndarray) -> float | None:
        return float(np.sqrt(np.mean(errors[mask] ** 2))) if mask.any() else None

    @property
    def rms_before_mm(self) -> float | None:
        return self._rms(self.errors_before, self.fit_mask)

    @property
    def rms_after_mm(self) -> float | None:
        return self._rms(self.errors_after, self.fit_mask)

    @property
    def _refined(self) -> bool:
        return self.verification is not None and self.verification.refined

    @property
    def check_rows(self) -> np.ndarray:
        """Rows of the check poses (after a refinement: those the fit-only geometry predicted)."""
        if self.verification is not None and self.verification.refined:
            return np.asarray(self.verification.rows, dtype=int)
        return np.flatnonzero(~self.fit_mask)

    @property
    def check_errors_after(self) -> np.ndarray:
        """Check poses' errors as predicted, not fitted (after a refinement: by the fit-only
        geometry, the verification's residuals)."""
        if self.verification is not None and self.verification.refined:
            return self.verification.errors_mm
        return np.asarray(self.errors_after[~self.fit_mask])

    @property
    def check_rms_before_mm(self) -> float | None:
        e = self.errors_before[self.check_rows]
        return float(np.sqrt(np.mean(e**2))) if e.size else None

    @property
    def check_rms_after_mm(self) -> float | None:
        e = self.check_errors_after
        return float(np.sqrt(np.mean(e**2))) if e.size else None

    @property
    def identifiable(self) -> bool:
        return not self.unidentifiable and bool(np.all(np.isfinite(self.stderr)))

    @property
    def solved(self) -> bool:
        """Converged on enough poses with every parameter determined (trusted or not)."""
        return self.converged and self.identifiable and self.poses_used >= MIN_POSES

    @property
    def ok(self) -> bool:
        """Solved and trusted by the gate."""
        return (
            self.solved
            and (self.trust is None or self.trust.trusted)
            and (self.verification is None or self.verification.problem() is None)
        )

    @property
    def predicted_workspace_rms_mm(self) -> float:
        return self.trust.predicted_rms_mm if self.trust else float("nan")

    @property
    def predicted_workspace_max_mm(self) -> float:
        return self.trust.predicted_max_mm if self.trust else float("nan")

    def problems(self) -> list[str]:
        out = []
        if self.poses_used < MIN_POSES:
            out.append(
                f"only {self.poses_used} usable fit pose(s); at least {MIN_POSES} are needed for 12 parameters"
            )
        if not self.converged and self.poses_used >= MIN_POSES:
            out.append("the least-squares fit did not converge")
        if self.unidentifiable:
            out.append("unidentifiable parameter combination(s): " + "; ".join(self.unidentifiable))
        if self.trust is not None:
            out += list(self.trust.refusals)
        problem = self.verification.problem() if self.verification else None
        if problem:
            out.append(problem)
        return out

    def warnings(self) -> list[str]:
        return list(self.notes) + (list(self.trust.warnings) if self.trust else [])

    def to_json(self) -> dict[str, Any]:
        """The machine-readable report (field names are part of the CLI contract)."""
        g, se = self.geometry, self.stderr
        numbers = (
            self.pose_numbers
            if self.pose_numbers is not None
            else np.arange(1, len(self.roles) + 1)
        )
        out = {
            "ok": self.ok,
            "problems": self.problems(),
            "warnings": self.warnings(),
            "parameters": {
                "outlets": g.outlets.tolist(),
                "initial_lengths": g.initial_lengths.tolist(),
            },
            "nominal": {
                "outlets": self.nominal.outlets.tolist(),
                "initial_lengths": self.nominal.initial_lengths.tolist(),
            },
            "stderr": {
                "outlets": np.reshape(json_safe(np.ravel(se[:9])), (3, 3)).tolist(),
                "initial_lengths": json_safe(np.ravel(se[9:])),
            },
            "ci95": {n: json_safe(np.ravel(self.ci95[i])) for i, n in enumerate(self.names)},
            "correlations": [{"a": a, "b": b, "r": r} for a, b, r in self.correlations],
            "singular_values": self.singular_values.tolist(),
            "unidentifiable": list(self.unidentifiable),
            "rms_before_mm": self.rms_before_mm,
            "rms_after_mm": self.rms_after_mm,
            "check_rms_before_mm": self.check_rms_before_mm,
            "check_rms_after_mm": self.check_rms_after_mm,
            "predicted_workspace_rms_mm": self.predicted_workspace_rms_mm,
            "predicted_workspace_max_mm": self.predicted_workspace_max_mm,
            "trust": self.trust.to_json() if self.trust else None,
            "verification": self.verification.to_json() if self.verification else None,
            "noise": self.noise.as_dict() if self.noise else None,
            "iterations": self.iterations,
            "converged": self.converged,
            "chi2": self.chi2,
            "dof": self.dof,
            "poses_used": self.poses_used,
            "poses": [
                {
                    "pose": int(numbers[i]),
                    "role": r,
                    "error_before_mm": float(b),
                    "error_after_mm": float(a),
                    "residual_mm": self.residuals_after[i].tolist(),
                    "sigma_mm": float(self.sigma_mm[i]),
                }
                for i, (r, b, a) in enumerate(
                    zip(self.roles, self.errors_before, self.errors_after)
                )
            ],
            "rejected": list(self.rejected),
        }
        return dict(json_safe(out))


def identify(
    obs: Observations,
    base: MachineModel,
    roles: tuple[str, ...] | list[str] | None = None,
    *,
    rejected: tuple[str, ...] = (),
    limits: TrustLimits = DEFAULT_TRUST,
    grid: np.ndarray | None = None,
    noise: PoseNoise | None = None,
    pose_numbers: np.ndarray | None = None,
    notes: tuple[str, ...] = (),
    alpha: float = DEFAULT_ALPHA,
) -> Identification:
    """Fit the geometry on the ``fit`` poses of ``obs``; predict every pose before/after;
    test the ``check`` poses against that prediction (:mod:`.verification`, false-alarm
    rate ``alpha``); judge the result with the trust gate over ``grid`` (default: the
    build volume)."""
    k = len(obs)
    roles = tuple(roles) if roles is not None else ("fit",) * k
    if len(roles) != k:
        raise ValueError(f"{len(roles)} roles for {k} poses")
    fit_idx = np.flatnonzero(np.array(roles) == "fit")
    # Noise-free simulations state sigma = 0; weights need a positive one.
    sigma = np.maximum(np.broadcast_to(np.asarray(obs.sigma_mm, dtype=float), (k,)), 1e-6)
    obs = obs.with_sigma(sigma)
    before = _errors(base, obs)
    common = {
        "rejected": rejected,
        "pose_numbers": pose_numbers,
        "noise": noise,
        "notes": notes,
    }
    if fit_idx.size < MIN_POSES:
        inf = np.full(12, np.inf)
        return Identification(
            base.geometry,
            base.geometry,
            inf,
            np.column_stack([-inf, inf]),
            [],
            np.zeros(0),
            [],
            roles,
            before,
            before,
            _residuals(base, obs),
            0,
            False,
            float("nan"),
            0,
            sigma,
            base,
            **common,  # type: ignore[arg-type]
        )
    est = CableModelFit(scale_covariance=False).fit(obs.subset(fit_idx), base)
    model = est.model_
    cov = np.array(est.covariance_[:12, :12])
    if est.null_space_.size:
        cov[:] = np.inf
    residuals = _residuals(model, obs)
    check = np.flatnonzero(np.array(roles) == "check")
    j0 = identification_jacobian(obs.measured[check], model.geometry).reshape(-1, 3, 12)
    own = (
        sigma[check, None, None] ** 2 * np.eye(3)
        if obs.covariance is None
        else np.asarray(obs.covariance)[check]
    )
    with np.errstate(invalid="ignore"):
        pred_cov = own + np.einsum("nip,pq,njq->nij", j0, np.where(np.isfinite(cov), cov, 0.0), j0)
    factor, noise_dof = variance_factor(est.chi2_, est.dof_, residuals[check], pred_cov)
    trust = trust_report(
        model.geometry,
        cov,
        est.information_[:12, :12],
        workspace_grid(base) if grid is None else grid,
        factor,
        noise_dof,
        limits,
        parameter_covariance=None if noise is None else noise.parameter_covariance,
        common_covariance=None if noise is None else noise.common_covariance,
        frame_covariance=None if noise is None else noise.frame_covariance,
    )
    numbers = np.arange(1, k + 1) if pose_numbers is None else np.asarray(pose_numbers)
    verification = (
        dataclasses.replace(
            verify_checks(residuals[check], sigma[check], j0, cov, numbers[check], alpha),
            fit_only_rms_mm=trust.predicted_rms_mm,
            fit_only_max_mm=trust.predicted_max_mm,
            rows=tuple(int(i) for i in check),
        )
        if check.size
        else None
    )
    inflate = max(factor, 1.0) if np.isfinite(factor) else 1.0
    cov = cov * inflate
    stderr = np.array(est.stderr_[:12]) * np.sqrt(inflate)
    q = stats.t.ppf(0.975, noise_dof) if noise_dof > 0 and inflate > 1.0 else stats.norm.ppf(0.975)
    x = est.x_[:12]
    return Identification(
        nominal=base.geometry,
        geometry=model.geometry,
        stderr=stderr,
        ci95=np.column_stack([x - q * stderr, x + q * stderr]),
        correlations=est.high_correlations(0.95),
        singular_values=est.singular_values_,
        unidentifiable=est.unidentifiable(),
        roles=roles,
        errors_before=before,
        errors_after=_errors(model, obs),
        residuals_after=residuals,
        iterations=est.iterations_,
        converged=est.converged_,
        chi2=est.chi2_,
        dof=est.dof_,
        sigma_mm=sigma,
        model=model,
        trust=trust,
        covariance=cov,
        verification=verification,
        **common,  # type: ignore[arg-type]
    )


def identify_verified(
    obs: Observations,
    base: MachineModel,
    roles: tuple[str, ...] | list[str] | None = None,
    *,
    refine: bool = True,
    **options: Any,
) -> Identification:
    """Verify, then refine: identify on the ``fit`` poses and test the ``check`` poses
    against that prediction; when they agree (and ``refine``), identify again on every
    pose, keeping the verification (with both predicted workspace errors) in the result.
    Options as for :func:`identify`."""
    first = identify(obs, base, roles, **options)
    v = first.verification
    if not refine or v is None or not v.consistent or not first.solved:
        return first
    second = identify(obs, base, ("fit",) * len(obs), **options)
    return dataclasses.replace(
        second,
        verification=dataclasses.replace(
            v,
            refined=True,
            refined_rms_mm=second.predicted_workspace_rms_mm,
            refined_max_mm=second.predicted_workspace_max_mm,
        ),
    )


def _errors(model: MachineModel, obs: Observations) -> np.ndarray:
    return np.asarray(np.linalg.norm(_residuals(model, obs), axis=1))


def _residuals(model: MachineModel, obs: Observations) -> np.ndarray:
    predicted = model.fk(obs.sliders, obs.context)
    return np.where(np.isfinite(predicted), predicted - obs.measured, np.inf)


def calibrated_profile(
    profile: MachineProfile, result: Identification, *, session: str = "", date: str | None = None
) -> MachineProfile:
    """``profile`` with the identified geometry and a ``calibration`` provenance table.

    A geometry the profile model refuses (outlets collinear, above the build volume...)
    raises :class:`~cdprhost.errors.JobFailed` naming each problem."""
    g = result.geometry
    provenance: dict[str, Any] = {
        "method": "cable-length residual least squares (12 geometric parameters)",
        "session": str(session),
        "date": date or _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "base_profile": profile.name,
        "poses_used": result.poses_used,
        "rms_before_mm": result.rms_before_mm,
        "rms_after_mm": result.rms_after_mm,
        "iterations": result.iterations,
        "stderr_outlets_mm": np.nan_to_num(result.stderr[:9], posinf=-1.0).reshape(3, 3).tolist(),
        "stderr_initial_lengths_mm": np.nan_to_num(result.stderr[9:], posinf=-1.0).tolist(),
    }
    if result.trust is not None and np.isfinite(result.trust.predicted_max_mm):
        provenance["predicted_workspace_rms_mm"] = result.trust.predicted_rms_mm
        provenance["predicted_workspace_max_mm"] = result.trust.predicted_max_mm
    if not result.ok:
        provenance["forced"] = True
    if result.check_rms_after_mm is not None:
        provenance["check_poses"] = int(result.check_rows.size)
        provenance["check_rms_before_mm"] = result.check_rms_before_mm
        provenance["check_rms_after_mm"] = result.check_rms_after_mm
    name = profile.name if profile.name.endswith("-calibrated") else f"{profile.name}-calibrated"
    try:
        return profile.with_geometry(
            g.outlets,
            g.initial_lengths,
            name=name,
            calibration=json_safe(provenance, drop_none=True),
        )
    except (ValidationError, ValueError) as exc:
        problems = (
            [f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()]
            if isinstance(exc, ValidationError)
            else [str(exc)]
        )
        raise JobFailed(
            "the identified geometry is not a valid profile; no profile written:\n"
            + "\n".join(f"  - {p}" for p in problems)
        ) from None
