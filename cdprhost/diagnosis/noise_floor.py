"""The noise floor a diagnosis judges against: what a take's frame scatter does not show.

A pose's measured position carries an accuracy error of its own (a camera's lens model and
depth, a mocap system's calibration) that its frame scatter cannot reveal; estimated from
the fit's residuals as a variance component (the chi-square solved for it) or along a given
covariance, and added to the noise the identification and the tests use."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from cdprhost.calibration.fitting import CableModelFit, Observations, position_misfit
from cdprhost.calibration.pose_noise import PoseNoise
from cdprhost.diagnosis.localise import localise
from cdprhost.diagnosis.stat_tests import goodness_of_fit_p
from cdprhost.kinematics.machine import MachineModel

MIN_ACCURACY_DOF = 6


def unseen_noise(fit: CableModelFit, obs: Observations, noise: PoseNoise) -> PoseNoise:
    """``noise`` plus the common part s that makes the fitted model's chi-square equal its
    degrees of freedom (sum r_i^2 / (sigma_i^2 + s^2) = dof, solved for s)."""
    sig = np.broadcast_to(np.asarray(obs.sigma_mm, dtype=float), (len(obs),))
    r2 = np.sum((fit.residuals_ * sig[:, None]) ** 2, axis=1)  # position misfit^2 per pose, mm^2
    extra = variance_component(r2, sig, max(fit.dof_, 1))
    return PoseNoise(
        np.sqrt(sig**2 + extra**2),
        noise.take_mm,
        extra,
        "takes + unstructured excess",
        f"the residuals exceed the takes' noise with no pattern (time, direction, tension, height, "
        f"slider position): {extra:.3g} mm per coordinate added to every pose as noise no take "
        "shows; declare noise_mm in session.toml, or repeat poses, to measure it",
    )


def variance_component(r2: np.ndarray, sig: np.ndarray, dof: int) -> float:
    """The common variance s^2 (returned as s, mm) that makes sum r2 / (sig^2 + s^2) = dof
    (0 when the chi-square is already within it)."""
    if np.sum(r2 / sig**2) <= dof:
        return 0.0
    lo, hi = 0.0, float(np.sqrt(np.max(r2))) + 1e-9
    for _ in range(60):  # bisection: the chi-square falls monotonically as s grows
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.sum(r2 / (sig**2 + mid**2)) > dof else (lo, mid)
    return 0.5 * (lo + hi)


def accuracy_from_fit(
    obs: Observations,
    start: MachineModel,
    effects: Sequence[str],
    noise: PoseNoise,
    alpha: float,
    localise_alpha: float = 0.01,
) -> PoseNoise | None:
    """The measuring system's accuracy at each place, which no take's scatter shows
    (calibration-session.md), estimated as a variance component of the richest model (the
    geometry and every candidate effect at once, so that no effect of the catalogue is taken
    for noise): None when that model's chi-square is within the takes' noise (goodness of
    fit p >= ``alpha``), it has too few degrees of freedom, or its residuals show a pattern
    (:func:`~.localise.localise`: physics the catalogue lacks, not accuracy)."""
    fit = CableModelFit(effects=tuple(effects)).fit(obs, start)
    if fit.dof_ < MIN_ACCURACY_DOF or goodness_of_fit_p(fit.chi2_, fit.dof_) >= alpha:
        return None
    sig = np.broadcast_to(np.asarray(obs.sigma_mm, dtype=float), (len(obs),))
    if obs.covariance is not None:
        extra = covariance_component(
            position_misfit(fit.model_, obs), np.asarray(obs.covariance, float), fit.dof_
        )
    else:
        r2 = np.sum((fit.residuals_ * sig[:, None]) ** 2, axis=1)
        extra = variance_component(r2, sig, fit.dof_)
    if extra <= 0:
        return None
    wider = np.sqrt(sig**2 + extra**2)
    widened = obs.with_sigma(wider)
    if localise(fit.model_, widened, localise_alpha):
        return None  # a pattern is physics the catalogue lacks, not accuracy
    return dataclasses.replace(
        noise,
        sigma_mm=np.sqrt(noise.sigma_mm**2 + extra**2),
        extra_mm=extra,
        source=f"{noise.source} + accuracy (fit)",
        note=f"the measuring system's accuracy, which no take's scatter shows: {extra:.3g} mm "
        "per coordinate, estimated as a variance component of the geometry fitted with every "
        "candidate effect (declare accuracy_mm in session.toml, or repeat poses, to measure it)",
        covariance=None if noise.covariance is None else noise.covariance + extra**2 * np.eye(3),
    )


def covariance_component(misfit: np.ndarray, covariance: np.ndarray, dof: int) -> float:
    """The common variance s^2 (returned as s, mm) added to every pose's covariance that
    makes sum m^T (C + s^2 I)^-1 m = dof (0 when already within it)."""

    def chi2(s: float) -> float:
        c = covariance + s * s * np.eye(3)
        return float(np.sum(misfit * np.linalg.solve(c, misfit[..., None])[..., 0]))

    if chi2(0.0) <= dof:
        return 0.0
    lo, hi = 0.0, float(np.sqrt(np.max(np.sum(misfit**2, axis=1)))) + 1e-9
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2(mid) > dof else (lo, mid)
    return 0.5 * (lo + hi)
