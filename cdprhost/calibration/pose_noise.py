"""The noise of each measured pose (mm per coordinate): one model for identification and
diagnosis.

A pose is measured by averaging a take, so its noise is the standard error of the take's
centre (autocorrelation-aware, registration included: :mod:`.takes`), not the frames'
scatter. Two things can add a part that no take shows, both added in quadrature:

- ``noise_mm`` declared in session.toml (``[mocap]`` or ``[session]``): what the user
  knows of the system's accuracy beyond its jitter (calibration, repeatability);
- repeated poses (the same slider steps commanded more than once): their pooled scatter
  beyond what the takes' standard errors explain (at least 6 degrees of freedom).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Fewest degrees of freedom of repeated poses before their scatter is believed.
MIN_REPEAT_DOF = 6


@dataclass(frozen=True, eq=False)
class PoseNoise:
    """``sigma_mm`` (K,): each pose's noise per coordinate; ``take_mm`` (K,) the takes' part;
    ``extra_mm`` the part added to every pose; ``source`` and ``note`` say where it came from."""

    sigma_mm: np.ndarray
    take_mm: np.ndarray
    extra_mm: float
    source: str
    note: str = ""
    # a camera's noise (camera-session.md): each pose's full covariance (K, 3, 3), mm^2
    # (sigma_mm is then sqrt(trace / 3)); the covariance of the one vector that moves every
    # pose alike (3, 3), which identification cannot see; and what the camera parameters'
    # uncertainty adds to the 12 geometric parameters (12, 12). The trust gate counts both.
    covariance: np.ndarray | None = None
    common_covariance: np.ndarray | None = None
    parameter_covariance: np.ndarray | None = None
    # (6, 6): a rigid error of the whole measuring frame (rotation vector about the base
    # origin, translation): a camera's pose from the reference board
    frame_covariance: np.ndarray | None = None

    @property
    def typical_mm(self) -> float:
        """RMS of the poses' noise."""
        s = np.asarray(self.sigma_mm, dtype=float)
        return float(np.sqrt(np.mean(s * s))) if s.size else float("nan")

    def as_dict(self) -> dict[str, Any]:
        return {
            "sigma_mm": self.typical_mm,
            "per_pose_mm": np.asarray(self.sigma_mm, dtype=float).tolist(),
            "take_mm": float(np.sqrt(np.mean(np.square(self.take_mm))))
            if self.take_mm.size
            else None,
            "extra_mm": self.extra_mm,
            "source": self.source,
            "note": self.note,
            "common_mm": None
            if self.common_covariance is None
            else float(np.sqrt(np.trace(self.common_covariance))),
            "depth_to_lateral": self.anisotropy,
        }

    @property
    def anisotropy(self) -> float | None:
        """Median over poses of the largest over the smallest principal std (a camera's depth
        against its lateral precision); None without full covariances."""
        if self.covariance is None or not len(self.covariance):
            return None
        w = np.linalg.eigvalsh(np.asarray(self.covariance, float))
        return float(np.median(np.sqrt(w[:, -1] / np.maximum(w[:, 0], 1e-300))))

    def subset(self, index: np.ndarray) -> PoseNoise:
        return PoseNoise(
            self.sigma_mm[index],
            self.take_mm[index],
            self.extra_mm,
            self.source,
            self.note,
            None if self.covariance is None else self.covariance[index],
            self.common_covariance,
            self.parameter_covariance,
            self.frame_covariance,
        )


def repeated_pose_scatter(
    sliders: np.ndarray,
    measured: np.ndarray,
    steps_per_mm: np.ndarray | float = 400.0,
    min_dof: int = MIN_REPEAT_DOF,
) -> tuple[float, int, np.ndarray] | None:
    """Pooled per-coordinate scatter of poses commanded to identical steps: (sigma, dof, mask of
    the repeated poses), or None when there are fewer than ``min_dof`` degrees of freedom."""
    steps = np.rint(np.asarray(sliders, float) * steps_per_mm).astype(np.int64)
    if steps.shape[0] == 0:
        return None
    _, group, counts = np.unique(steps, axis=0, return_inverse=True, return_counts=True)
    group = group.ravel()
    repeated = counts[group] > 1
    if not repeated.any():
        return None
    g = group[repeated]
    m = np.asarray(measured, float)[repeated]
    sums = np.zeros((counts.size, 3))
    np.add.at(sums, g, m)
    dev = m - (sums / counts[:, None])[g]
    dof = 3 * int(repeated.sum() - np.unique(g).size)
    if dof < min_dof:
        return None
    return math.sqrt(float(np.sum(dev * dev)) / dof), dof, repeated


def pose_noise(
    take_sigma_mm: np.ndarray,
    *,
    declared_mm: float | None = None,
    sliders: np.ndarray | None = None,
    measured: np.ndarray | None = None,
    steps_per_mm: np.ndarray | float = 400.0,
) -> PoseNoise:
    """Each pose's noise from its take's standard error, plus a declared or replicate part."""
    take = np.asarray(take_sigma_mm, dtype=float).reshape(-1)
    if declared_mm is not None and math.isfinite(declared_mm) and declared_mm > 0:
        extra = float(declared_mm)
        return PoseNoise(
            np.sqrt(take**2 + extra**2),
            take,
            extra,
            "takes + declared",
            f"take standard errors plus noise_mm = {extra:g} declared in session.toml",
        )
    if sliders is not None and measured is not None:
        rep = repeated_pose_scatter(sliders, measured, steps_per_mm)
        if rep is not None:
            scatter, dof, mask = rep
            expected = float(np.sqrt(np.mean(take[mask] ** 2)))
            extra = math.sqrt(max(scatter**2 - expected**2, 0.0))
            return PoseNoise(
                np.sqrt(take**2 + extra**2),
                take,
                extra,
                "takes + repeated poses",
                f"repeated poses scatter {scatter:.3g} mm ({dof} dof) where the takes explain "
                f"{expected:.3g} mm: {extra:.3g} mm added to every pose",
            )
    return PoseNoise(take.copy(), take, 0.0, "takes", "standard error of each take's centre")


def camera_noise(
    covariance: np.ndarray,
    take_sigma_mm: np.ndarray,
    declared_mm: float | None = None,
    common_covariance: np.ndarray | None = None,
    parameter_covariance: np.ndarray | None = None,
    frame_covariance: np.ndarray | None = None,
) -> PoseNoise:
    """A camera session's pose noise: each pose's covariance from its corners' noise through
    the pose solution (anisotropic), plus a declared accuracy in quadrature; the parts that
    are the same for every pose travel with it for the trust gate."""
    cov = np.asarray(covariance, dtype=float)
    extra = float(declared_mm) if declared_mm is not None and declared_mm > 0 else 0.0
    if extra:
        cov = cov + extra**2 * np.eye(3)
    sigma = np.sqrt(np.trace(cov, axis1=1, axis2=2) / 3.0)
    note = "each pose's covariance from its corners' noise through the camera (depth worst)"
    if extra:
        note += f", plus accuracy_mm = {extra:g} declared"
    return PoseNoise(
        sigma,
        np.asarray(take_sigma_mm, float),
        extra,
        "camera" + (" + declared" if extra else ""),
        note,
        cov,
        common_covariance,
        parameter_covariance,
        frame_covariance,
    )
