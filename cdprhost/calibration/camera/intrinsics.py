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

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.detection import BoardDetection

#: Fewest views calibrateCamera is given, and fewest for a trusted result.
MIN_VIEWS, MIN_GOOD_VIEWS = 3, 8
#: The image is divided in GRID x GRID cells for the coverage check.
GRID = 4

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
    fit_k3: bool = False,
) -> IntrinsicsResult:
    """Intrinsics from ChArUco views of ``board`` (None = board not found in that view;
    views with fewer than ``min_corners`` corners are dropped, with the reason). Raises
    ValueError when fewer than 3 views are usable; a result whose ``coverage.ok`` is False
    must be refused by the caller (exit 1) with ``problems``."""
    used: list[int] = []
    dropped: list[tuple[int, str]] = []
    obj, img = [], []
    for i, d in enumerate(detections):
        if d is None:
            dropped.append((i, "board not found"))
        elif len(d) < min_corners:
            dropped.append((i, f"only {len(d)} corners (need {min_corners})"))
        elif tuple(d.image_size) != tuple(image_size):
            dropped.append((i, f"image size {d.image_size} is not {tuple(image_size)}"))
        else:
            used.append(i)
            obj.append(board.corners_mm[d.ids].astype(np.float32))
            img.append(d.corners_px.astype(np.float32).reshape(-1, 1, 2))
    if len(used) < MIN_VIEWS:
        raise ValueError(
            f"only {len(used)} usable calibration view(s) of {len(detections)} (need at least "
            f"{MIN_VIEWS}): " + "; ".join(f"view {i + 1}: {why}" for i, why in dropped[:10])
        )
    w, h = image_size
    f0 = 0.9 * max(w, h)
    k0 = np.array([[f0, 0, (w - 1) / 2], [0, f0, (h - 1) / 2], [0, 0, 1]])
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | (0 if fit_k3 else cv2.CALIB_FIX_K3)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-10)
    rms, k, dist, rvecs, _, std_i, _, per_view = cv2.calibrateCameraExtended(
        obj, img, (w, h), k0, np.zeros(5), flags=flags, criteria=crit
    )
    std = np.asarray(std_i, float).ravel()[:9]
    if not fit_k3:
        std[8] = 0.0
    intr = Intrinsics(
        np.asarray(k, float),
        np.asarray(dist, float).ravel()[:5],
        (int(w), int(h)),
        std,
        float(rms),
    )
    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rvecs])
    coverage = judge_coverage(
        [d for d in (detections[i] for i in used) if d is not None], normals, (w, h)
    )
    return IntrinsicsResult(
        intr, float(rms), np.asarray(per_view, float).ravel(), coverage, tuple(used), tuple(dropped)
    )


def judge_coverage(
    detections: list[BoardDetection],
    normals: np.ndarray,
    image_size: tuple[int, int],
    *,
    min_cell_fraction: float = 0.75,
    min_tilt_deg: float = 20.0,
    axis_tilt_deg: float = 12.0,
) -> Coverage:
    """Do corners reach the image (a 4 x 4 grid of cells, all four corner cells) and is the
    board tilted enough, about both image axes? ``normals`` (V, 3) board z axes in the
    camera frame."""
    w, h = image_size
    hit = np.zeros((GRID, GRID), bool)
    for d in detections:
        c = np.clip((d.corners_px / np.array([w, h]) * GRID).astype(int), 0, GRID - 1)
        hit[c[:, 1], c[:, 0]] = True
    fraction = float(hit.mean())
    corner_names = {
        (0, 0): "top-left",
        (0, GRID - 1): "top-right",
        (GRID - 1, 0): "bottom-left",
        (GRID - 1, GRID - 1): "bottom-right",
    }
    missing = [name for (r, c), name in corner_names.items() if not hit[r, c]]
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    tilt = np.degrees(np.arccos(np.clip(np.abs(n[:, 2]), 0, 1)))
    about_x = np.degrees(
        np.arcsin(np.clip(np.abs(n[:, 1]), 0, 1))
    )  # tilt about the image's horizontal axis
    about_y = np.degrees(np.arcsin(np.clip(np.abs(n[:, 0]), 0, 1)))
    axes = int(about_x.max(initial=0) >= axis_tilt_deg) + int(
        about_y.max(initial=0) >= axis_tilt_deg
    )
    max_tilt = float(tilt.max(initial=0.0))
    reasons, advice = [], []
    if len(detections) < MIN_GOOD_VIEWS:
        reasons.append(f"only {len(detections)} usable views (need {MIN_GOOD_VIEWS})")
        advice.append(f"take at least {MIN_GOOD_VIEWS - len(detections)} more views")
    if fraction < min_cell_fraction or missing:
        empty = [f"row {r + 1} col {c + 1}" for r, c in zip(*np.nonzero(~hit))]
        reasons.append(
            f"corners cover {fraction:.0%} of the image's {GRID}x{GRID} cells (need {min_cell_fraction:.0%}"
            + (f", and every corner of the image; missing: {', '.join(missing)}" if missing else "")
            + ")"
        )
        advice.append(
            "add views with the board near "
            + (", ".join(missing) if missing else "the empty cells")
            + f" (empty cells: {', '.join(empty[:8])}{' ...' if len(empty) > 8 else ''})"
        )
    if max_tilt < min_tilt_deg or axes < 2:
        reasons.append(
            f"the board is tilted at most {max_tilt:.0f} deg (need {min_tilt_deg:g}), about the "
            f"image's horizontal axis up to {about_x.max(initial=0):.0f} deg and its vertical "
            f"axis up to {about_y.max(initial=0):.0f} deg (need {axis_tilt_deg:g} about each): "
            "face-on views leave focal length and distance traded off"
        )
        advice.append("add views with the board tilted 20-45 deg to the left/right and up/down")
    ok = not reasons
    return Coverage(
        ok,
        "; ".join(reasons) if reasons else "views cover the image and tilt enough",
        "; ".join(advice),
        fraction,
        4 - len(missing),
        max_tilt,
        axes,
    )
