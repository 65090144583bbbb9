"""Camera intrinsics: the pinhole matrix and OpenCV's 5-term distortion, with uncertainty.

:func:`calibrate_intrinsics` solves them from ChArUco views (``cv2.calibrateCameraExtended``
on sub-pixel corners), reports the reprojection error and each parameter's standard
deviation, and refuses views that cannot pin them down (:class:`Coverage`): corners must
reach the image's edges and corners, and the board must be seen tilted in more than one
direction (a set of face-on views leaves the focal length and the depth traded off).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.detection import BoardDetection

#: Order of :attr:`Intrinsics.std` and of the refinable parameters.
PARAMETER_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


@dataclass(frozen=True, eq=False)
class Intrinsics:
    """``matrix`` (3, 3) px; ``distortion`` (5,) OpenCV order k1, k2, p1, p2, k3;
    ``image_size`` (width, height) px; ``std`` (9,) standard deviation of
    (fx, fy, cx, cy, k1, k2, p1, p2, k3), NaN where unknown; ``rms_reprojection_px``."""

    matrix: np.ndarray
    distortion: np.ndarray
    image_size: tuple[int, int]
    std: np.ndarray = field(default_factory=lambda: np.full(9, np.nan))
    rms_reprojection_px: float | None = None

    @property
    def vector(self) -> np.ndarray:
        """(fx, fy, cx, cy, k1, k2, p1, p2, k3)."""
        k = np.asarray(self.matrix, float)
        return np.concatenate([[k[0, 0], k[1, 1], k[0, 2], k[1, 2]], self.distortion_5])

    @property
    def distortion_5(self) -> np.ndarray:
        d = np.zeros(5)
        src = np.asarray(self.distortion, float).ravel()[:5]
        d[: src.size] = src
        return d

    @classmethod
    def from_vector(
        cls,
        v: np.ndarray,
        image_size: tuple[int, int],
        std: np.ndarray | None = None,
        rms_reprojection_px: float | None = None,
    ) -> Intrinsics:
        k = np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]])
        return cls(
            k,
            np.asarray(v[4:9], float).copy(),
            image_size,
            np.full(9, np.nan) if std is None else np.asarray(std, float),
            rms_reprojection_px,
        )

    def covariance(self, default_rel: float = 0.0) -> np.ndarray:
        """(9, 9) diagonal covariance from ``std`` (NaN -> 0, or ``default_rel`` x value)."""
        s = np.asarray(self.std, float)
        s = np.where(np.isfinite(s), s, default_rel * np.abs(self.vector))
        return np.diag(s**2)

    def to_json(self) -> dict[str, Any]:
        return {
            "image_size": list(self.image_size),
            "matrix": np.asarray(self.matrix, float).tolist(),
            "distortion": self.distortion_5.tolist(),
            "std": {
                n: (float(s) if np.isfinite(s) else None) for n, s in zip(PARAMETER_NAMES, self.std)
            },
            "rms_reprojection_px": self.rms_reprojection_px,
        }


@dataclass(frozen=True)
class Coverage:
    """Do the views pin the intrinsics down? ``ok``; ``reason`` (why not); ``advice`` (which
    views to add); the measured figures: fraction of the image's 4x4 cells (and of its four
    corner cells) that corners reached, and the spread of board tilts (degrees)."""

    ok: bool
    reason: str
    advice: str
    cell_fraction: float
    corner_cells: int
    max_tilt_deg: float
    tilt_axes: int  # distinct tilt directions seen (0, 1 or 2)


@dataclass(frozen=True, eq=False)
class IntrinsicsResult:
    """The calibration: intrinsics (with ``std``), RMS and per-view reprojection error (px),
    the coverage verdict, the views used (their index in the input) and those dropped with why."""

    intrinsics: Intrinsics
    rms_px: float
    per_view_px: np.ndarray
    coverage: Coverage
    views_used: tuple[int, ...]
    views_dropped: tuple[tuple[int, str], ...] = ()

    @property
    def ok(self) -> bool:
        return self.coverage.ok

    @property
    def problems(self) -> list[str]:
        return [] if self.coverage.ok else [f"{self.coverage.reason}; {self.coverage.advice}"]


def calibrate_intrinsics(
    detections: list[BoardDetection | None],
    board: CharucoBoard,
    image_size: tuple[int, int],
    *,
    min_corners: int = 8,
) -> IntrinsicsResult:
    """Intrinsics from ChArUco views of ``board`` (None = board not found in that view;
    views with fewer than ``min_corners`` corners are dropped, with the reason). Raises
    ValueError when fewer than 3 views are usable; a result whose ``coverage.ok`` is False
    must be refused by the caller (exit 1) with ``problems``."""
    raise NotImplementedError
