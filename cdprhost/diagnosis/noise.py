"""The measurement noise sigma (mm per coordinate) the chi-square tests rely on.

Sources, best first:
1. declared in ``session.toml`` as ``noise_mm = 0.05`` under ``[session]`` (or under
   ``[mocap]`` once the session model accepts it) (the mocap system's
   accuracy for a static averaged point, from its calibration report);
2. repeated poses: poses commanded to the same slider steps more than once, pooled
   within-group scatter of the measured points (needs >= 6 degrees of freedom);
3. a default of 0.05 mm, with a note saying so; per-take frame scatter is only a
   lower bound (it misses errors that stay fixed during a take), so it replaces
   the default only when it is larger.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DEFAULT_NOISE_MM = 0.05


@dataclass(frozen=True)
class NoiseEstimate:
    sigma_mm: float
    source: str  # "declared" | "repeated poses" | "take scatter" | "default"
    note: str = ""

    def as_dict(self) -> dict:
        return {"sigma_mm": self.sigma_mm, "source": self.source, "note": self.note}


def repeated_pose_sigma(
    sliders: np.ndarray,
    measured: np.ndarray,
    steps_per_mm: np.ndarray | float = 400.0,
    min_dof: int = 6,
) -> tuple[float, int] | None:
    """Pooled per-coordinate scatter of poses commanded to identical steps; (sigma, dof) or None."""
    steps = np.rint(np.asarray(sliders, float) * steps_per_mm).astype(np.int64)
    _, group, counts = np.unique(steps, axis=0, return_inverse=True, return_counts=True)
    group = group.ravel()
    repeated = counts[group] > 1
    if not repeated.any():
        return None
    g = group[repeated]
    m = np.asarray(measured, float)[repeated]
    sums = np.zeros((counts.size, 3))
    np.add.at(sums, g, m)
    means = sums / counts[:, None]
    dev = m - means[g]
    dof = 3 * int(repeated.sum() - np.unique(g).size)
    if dof < min_dof:
        return None
    return math.sqrt(float(np.sum(dev * dev)) / dof), dof


def estimate_noise(
    declared_mm: float | None = None,
    *,
    sliders: np.ndarray | None = None,
    measured: np.ndarray | None = None,
    steps_per_mm: np.ndarray | float = 400.0,
    take_std_mm: np.ndarray | None = None,
) -> NoiseEstimate:
    """Pick sigma from the best available source (see module docstring)."""
    if declared_mm is not None and math.isfinite(declared_mm) and declared_mm > 0:
        return NoiseEstimate(float(declared_mm), "declared", "noise_mm declared in session.toml")
    if sliders is not None and measured is not None:
        rep = repeated_pose_sigma(sliders, measured, steps_per_mm)
        if rep is not None:
            return NoiseEstimate(
                rep[0], "repeated poses", f"pooled scatter of repeated poses ({rep[1]} dof)"
            )
    note = f"no noise declared (noise_mm in session.toml) and no repeated poses: assumed {DEFAULT_NOISE_MM} mm"
    if take_std_mm is not None:
        std = np.asarray(take_std_mm, float)
        std = std[np.isfinite(std)]
        scatter = float(np.sqrt(np.median(std * std))) if std.size else 0.0
        if scatter > DEFAULT_NOISE_MM:
            return NoiseEstimate(
                scatter,
                "take scatter",
                "frame-to-frame scatter within takes exceeds the default; static errors not included",
            )
        if scatter > 0:
            note += f" (frame scatter within takes, {scatter:.3g} mm, is only a lower bound)"
    return NoiseEstimate(DEFAULT_NOISE_MM, "default", note)
