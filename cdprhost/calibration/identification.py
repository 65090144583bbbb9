"""Identification of the 12 geometric parameters from measured poses.

A thin layer over :class:`~cdprhost.calibration.fitting.CableModelFit` (the one
estimator): it fits the poses marked ``fit``, predicts the ``check`` poses, and
gathers what a user needs to trust the result: standard errors and 95 %
intervals, high correlations, scaled singular values with the unidentifiable
combinations named, per-pose errors, RMS before and after. The profile's own
effects are held at their values while the geometry is fitted.
"""

from __future__ import annotations

import csv
import datetime as _dt
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from cdprhost.calibration.fitting import GEOMETRY_NAMES, CableModelFit, Observations
from cdprhost.calibration.session import POSES_FILE, load_session
from cdprhost.errors import InputError
from cdprhost.jsonsafe import json_safe
from cdprhost.kinematics.geometry import CableGeometry
from cdprhost.kinematics.machine import MachineModel
from cdprhost.profile.models import MachineProfile

MIN_POSES = 4
ROLES = ("fit", "check")


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

    names = GEOMETRY_NAMES

    @property
    def fit_mask(self) -> np.ndarray:
        return np.array(self.roles) == "fit"

    @property
    def poses_used(self) -> int:
        return int(self.fit_mask.sum())

    def _rms(self, errors: np.ndarray, mask: np.ndarray) -> float | None:
        return float(np.sqrt(np.mean(errors[mask] ** 2))) if mask.any() else None

    @property
    def rms_before_mm(self) -> float:
        return self._rms(self.errors_before, self.fit_mask)

    @property
    def rms_after_mm(self) -> float:
        return self._rms(self.errors_after, self.fit_mask)

    @property
    def check_rms_before_mm(self) -> float | None:
        return self._rms(self.errors_before, ~self.fit_mask)

    @property
    def check_rms_after_mm(self) -> float | None:
        return self._rms(self.errors_after, ~self.fit_mask)

    @property
    def identifiable(self) -> bool:
        return not self.unidentifiable and bool(np.all(np.isfinite(self.stderr)))

    @property
    def ok(self) -> bool:
        return self.converged and self.identifiable and self.poses_used >= MIN_POSES

    def problems(self) -> list[str]:
        out = []
        if self.poses_used < MIN_POSES:
            out.append(
                f"only {self.poses_used} usable fit pose(s); at least {MIN_POSES} are needed for 12 parameters"
            )
        if not self.converged:
            out.append("the least-squares fit did not converge")
        if self.unidentifiable:
            out.append("unidentifiable parameter combination(s): " + "; ".join(self.unidentifiable))
        return out

    def to_json(self) -> dict[str, Any]:
        """The machine-readable report (field names are part of the CLI contract)."""
        g, se = self.geometry, self.stderr

        return {
            "ok": self.ok,
            "problems": self.problems(),
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
            "iterations": self.iterations,
            "converged": self.converged,
            "chi2": self.chi2,
            "dof": self.dof,
            "poses_used": self.poses_used,
            "poses": [
                {
                    "pose": i + 1,
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


def identify(
    obs: Observations,
    base: MachineModel,
    roles: tuple[str, ...] | list[str] | None = None,
    *,
    rejected: tuple[str, ...] = (),
) -> Identification:
    """Fit the geometry on the ``fit`` poses of ``obs``; predict every pose before/after."""
    k = len(obs)
    roles = tuple(roles) if roles is not None else ("fit",) * k
    if len(roles) != k:
        raise ValueError(f"{len(roles)} roles for {k} poses")
    fit_idx = np.flatnonzero(np.array(roles) == "fit")
    # Noise-free simulations state sigma = 0; weights need a positive one.
    sigma = np.maximum(np.broadcast_to(np.asarray(obs.sigma_mm, dtype=float), (k,)), 1e-6)
    obs = Observations(obs.measured, obs.sliders, obs.t_s, obs.directions, sigma)
    before = _errors(base, obs)
    if fit_idx.size < MIN_POSES:
        nan = np.full(12, np.inf)
        return Identification(
            base.geometry,
            base.geometry,
            nan,
            np.column_stack([-nan, nan]),
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
            rejected,
        )
    est = CableModelFit(scale_covariance=False).fit(obs.subset(fit_idx), base)
    # Known-noise covariance, inflated (never shrunk) when the misfit exceeds the noise.
    inflate = max(1.0, est.chi2_ / est.dof_) if est.dof_ > 0 else 1.0
    stderr = est.stderr_[:12] * np.sqrt(inflate)
    q = stats.t.ppf(0.975, est.dof_) if est.dof_ > 0 and inflate > 1.0 else stats.norm.ppf(0.975)
    x = est.x_[:12]
    model = est.model_
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
        residuals_after=_residuals(model, obs),
        iterations=est.iterations_,
        converged=est.converged_,
        chi2=est.chi2_,
        dof=est.dof_,
        sigma_mm=sigma,
        model=model,
        rejected=rejected,
    )


def _errors(model: MachineModel, obs: Observations) -> np.ndarray:
    return np.linalg.norm(_residuals(model, obs), axis=1)


def _residuals(model: MachineModel, obs: Observations) -> np.ndarray:
    predicted = model.fk(obs.sliders, obs.context)
    return np.where(np.isfinite(predicted), predicted - obs.measured, np.inf)


def calibrated_profile(
    profile: MachineProfile, result: Identification, *, session: str = "", date: str | None = None
) -> MachineProfile:
    """``profile`` with the identified geometry and a ``calibration`` provenance table."""
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
    if result.check_rms_after_mm is not None:
        provenance["check_poses"] = int((~result.fit_mask).sum())
        provenance["check_rms_before_mm"] = result.check_rms_before_mm
        provenance["check_rms_after_mm"] = result.check_rms_after_mm
    name = profile.name if profile.name.endswith("-calibrated") else f"{profile.name}-calibrated"
    return profile.with_geometry(g.outlets, g.initial_lengths, name=name, calibration=provenance)


def pose_roles(poses_csv: str | os.PathLike[str]) -> dict[int, str]:
    """The optional ``role`` column of poses.csv (``fit`` | ``check``), by pose number; absent = fit."""
    with open(poses_csv, encoding="utf-8-sig", newline="") as fh:
        rows = list(csv.reader(fh))
    header = [h.strip() for h in rows[0]] if rows else []
    if "role" not in header:
        return {}
    ip, ir = header.index("pose"), header.index("role")
    roles: dict[int, str] = {}
    for n, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        role = (row[ir].strip().lower() if ir < len(row) else "") or "fit"
        if role not in ROLES:
            raise InputError(
                f"line {n}, column 'role' (column {ir + 1}): must be fit or check, got {role!r}",
                source=str(poses_csv),
            )
        roles[int(row[ip])] = role
    return roles


def identify_session(
    directory: str | os.PathLike[str], base: MachineModel, *, noise_floor_mm: float = 0.05
) -> Identification:
    """Measure every take of a session folder and identify (rejected takes are listed, not used).

    Each pose's sigma combines the take's frame noise (standard error of its mean)
    with the mocap noise floor, which averaging over frames cannot remove.
    """
    session = load_session(directory)
    meas = session.measure()
    if len(meas) == 0:
        raise InputError(
            "no usable take in the session",
            source=str(directory),
            problems=[f"pose {r.pose} ({r.take}): {r.message}" for r in meas.rejected],
        )
    roles_by_pose = pose_roles(Path(directory) / POSES_FILE)
    roles = tuple(roles_by_pose.get(int(p), "fit") for p in meas.pose)
    sem = np.array([t.sem for t in meas.takes]).reshape(-1, 3)
    sigma = np.sqrt(noise_floor_mm**2 + np.mean(sem**2, axis=1))
    obs = Observations(meas.measured, meas.s_cmd, meas.t_s, meas.dirs.astype(float), sigma)
    rejected = tuple(f"pose {r.pose} ({r.take}): {r.reason}: {r.message}" for r in meas.rejected)
    return identify(obs, base, roles, rejected=rejected)
