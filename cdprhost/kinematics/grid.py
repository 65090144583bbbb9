"""Points on a grid over the build volume, inside every workspace rule: where calibration
results are validated and where predicted position errors are evaluated."""

from __future__ import annotations

import numpy as np

from cdprhost.kinematics.machine import MachineModel


def workspace_grid(
    model: MachineModel,
    heights: tuple[float, ...] = (120.0, 170.0, 220.0, 270.0, 320.0),
    spacing_mm: float = 15.0,
) -> np.ndarray:
    """Points of the build volume (inside every workspace rule) on a grid at several heights."""
    side = model.limits.build_side
    xs = np.arange(-side / 2, side / 2 + 1e-9, spacing_mm)
    ys = np.arange(-side / np.sqrt(3) / 2, side / np.sqrt(3) + 1e-9, spacing_mm)
    gx, gy, gz = np.meshgrid(xs, ys, np.asarray(heights, float), indexing="ij")
    pts = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    return pts[model.check(pts).ok]
