"""Calibration views of a ChArUco board: positions over the image and tilts (test data)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.intrinsics import Intrinsics
from tests.calibration_camera.render import render


def view_poses(
    intr: Intrinsics,
    board: CharucoBoard,
    rng: np.random.Generator,
    n: int = 12,
    distance_mm: float = 600.0,
    max_tilt_deg: float = 35.0,
    spread: float = 0.8,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(R, t) board -> camera for ``n`` views whose centres sweep the image (``spread`` of
    its half-size) with tilts about both axes up to ``max_tilt_deg``."""
    w, h = intr.image_size
    k = np.asarray(intr.matrix)
    bw, bh = board.size_mm
    out = []
    grid = [(u, v) for v in (-1, 0, 1) for u in (-1, 0, 1)]
    for i in range(n):
        u, v = grid[i % len(grid)] if i < len(grid) else rng.uniform(-1, 1, 2)
        px = np.array([w / 2 + u * spread * w / 2, h / 2 + v * spread * h / 2])
        z = distance_mm * rng.uniform(0.85, 1.15)
        centre = np.array([(px[0] - k[0, 2]) / k[0, 0] * z, (px[1] - k[1, 2]) / k[1, 1] * z, z])
        tilt = rng.uniform(-max_tilt_deg, max_tilt_deg, 2)
        rot = Rotation.from_euler("xyz", [tilt[0], tilt[1], rng.uniform(-15, 15)], degrees=True)
        r = rot.as_matrix()
        t = centre - r @ np.array([bw / 2, bh / 2, 0.0])
        out.append((r, t))
    return out


def render_views(intr: Intrinsics, board: CharucoBoard, poses, rng, **kw) -> list[np.ndarray]:
    return [render([(board, r, t)], intr, rng=rng, **kw) for r, t in poses]
