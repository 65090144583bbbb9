"""Camera intrinsics: the pinhole matrix and OpenCV's 5-term distortion, with uncertainty.

:func:`calibrate_intrinsics` solves them from ChArUco views (``cv2.calibrateCamera`` on
sub-pixel corners for a start, then :func:`~.bowed_fit.refine_intrinsics`: the printed
board's bow fitted with the lens, and the tangential and k3 terms only where the views
observe them), reports the reprojection error and each parameter's standard
deviation, and refuses views that cannot pin them down (:class:`Coverage`): the predicted
reprojection uncertainty must be small where the machine's boards are seen (the middle of
the image unless a session says where), and the board must be seen tilted in more than one
direction (a set of face-on views leaves the focal length and the depth traded off).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.bowed_fit import refine_intrinsics
from cdprhost.calibration.camera.detection import BoardDetection
from cdprhost.calibration.camera.reprojection_uncertainty import middle_region, reprojection_sd

#: Fewest views calibrateCamera is given, and fewest for a trusted result.
MIN_VIEWS, MIN_GOOD_VIEWS = 3, 8
#: The image is divided in GRID x GRID cells for the coverage figures and advice.
GRID = 4
#: Largest predicted reprojection uncertainty (px) where the machine's boards are seen.
MAX_REGION_SD_PX = 0.15
#: Points of the region the uncertainty is evaluated at (at most).
MAX_REGION_POINTS = 300

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
    #: the calibration board's fitted bow (mm, middle against edges), when calibrated here
    board_bow_mm: float | None = None

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
    """Do the views pin the intrinsics down where the machine's boards are seen? ``ok``;
    ``reason`` (why not); ``advice`` (which views to add); the measured figures: fraction
    of the image's 4x4 cells (and of its four corner cells) that corners reached, the
    spread of board tilts (degrees), and the largest predicted reprojection uncertainty
    (px) over the region that matters (``region_sd_px``; NaN when not computed)."""

    ok: bool
    reason: str
    advice: str
    cell_fraction: float
    corner_cells: int
    max_tilt_deg: float
    tilt_axes: int  # distinct tilt directions seen (0, 1 or 2)
    region_sd_px: float = float("nan")
    region: str = "the middle of the image"


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
    covariance: np.ndarray | None = None  # (9, 9) of ``intrinsics.vector``
    normals: np.ndarray | None = None  # (V, 3) board z axes of the views used (camera)
    detections: tuple[BoardDetection, ...] = ()  # of the views used

    def judged_for(self, region_px: np.ndarray, region: str) -> IntrinsicsResult:
        """The same calibration with its coverage judged over ``region_px`` (N, 2): where
        the machine's boards are seen (``region`` names it)."""
        if self.covariance is None or self.normals is None:
            return self
        coverage = judge_coverage(
            list(self.detections),
            self.normals,
            self.intrinsics.image_size,
            vector=self.intrinsics.vector,
            covariance=self.covariance,
            region_px=region_px,
            region=region,
        )
        return replace(self, coverage=coverage)

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
    min_corners: int = 6,
    fit_k3: bool | None = None,
    missing: Mapping[int, str] | None = None,
) -> IntrinsicsResult:
    """Intrinsics from ChArUco views of ``board`` (None = board not found in that view;
    views with fewer than ``min_corners`` corners are dropped, with the reason: a view
    that shows part of the board counts). ``fit_k3`` None: k3 is fitted when the views
    observe it (as p1, p2 are); True/False: always/never. ``missing``: why the board is
    not found in some views (by index; default "board not found"). Raises
    ValueError when fewer than 3 views are usable; a result whose ``coverage.ok`` is False
    must be refused by the caller (exit 1) with ``problems``."""
    used: list[int] = []
    dropped: list[tuple[int, str]] = []
    obj, img = [], []
    for i, d in enumerate(detections):
        if d is None:
            dropped.append((i, (missing or {}).get(i, "board not found")))
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
    # a start: OpenCV's flat-board fit with the radial terms only
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-10)
    _rms, k, dist, rvecs, tvecs = cv2.calibrateCamera(
        obj, img, (w, h), k0, np.zeros(5), flags=flags, criteria=crit
    )
    start = np.concatenate(
        [[k[0, 0], k[1, 1], k[0, 2], k[1, 2]], np.asarray(dist, float).ravel()[:5]]
    )
    fit = refine_intrinsics(
        obj,
        img,
        start,
        np.asarray(rvecs, float).reshape(-1, 3),
        np.asarray(tvecs, float).reshape(-1, 3),
        board.corners_mm,
        fit_k3=fit_k3,
    )
    rms = fit.rms_px
    intr = replace(
        Intrinsics.from_vector(fit.vector, (int(w), int(h)), fit.std, rms),
        board_bow_mm=fit.bow_mm,
    )
    per_view = fit.per_view_px
    rvecs = list(fit.rvecs)
    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rvecs])
    seen = tuple(d for d in (detections[i] for i in used) if d is not None)
    coverage = judge_coverage(
        list(seen), normals, (w, h), vector=fit.vector, covariance=fit.covariance
    )
    return IntrinsicsResult(
        intr,
        float(rms),
        np.asarray(per_view, float).ravel(),
        coverage,
        tuple(used),
        tuple(dropped),
        fit.covariance,
        normals,
        seen,
    )


def judge_coverage(
    detections: list[BoardDetection],
    normals: np.ndarray,
    image_size: tuple[int, int],
    *,
    vector: np.ndarray | None = None,
    covariance: np.ndarray | None = None,
    region_px: np.ndarray | None = None,
    region: str = "the middle of the image",
    max_region_sd_px: float = MAX_REGION_SD_PX,
    min_tilt_deg: float = 20.0,
    axis_tilt_deg: float = 12.0,
) -> Coverage:
    """Do the views pin the lens down where it matters, and is the board tilted enough,
    about both image axes? The first is the predicted reprojection uncertainty
    (:func:`~.reprojection_uncertainty.reprojection_sd`, from ``vector`` and its
    ``covariance``) over ``region_px`` (where the machine's boards are seen; default the
    middle of the image): at most ``max_region_sd_px``. An image corner no view reached
    matters only if the boards are seen there. ``normals`` (V, 3) board z axes in the
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
    region_sd = float("nan")
    if vector is not None and covariance is not None:
        pts = middle_region((w, h)) if region_px is None else np.asarray(region_px, float)
        pts = pts.reshape(-1, 2)
        if len(pts) > MAX_REGION_POINTS:
            pts = pts[np.linspace(0, len(pts) - 1, MAX_REGION_POINTS).astype(int)]
        sd = reprojection_sd(vector, covariance, pts)
        region_sd = float(sd.max(initial=0.0))
        if region_sd > max_region_sd_px:
            cells = np.clip((pts / np.array([w, h]) * GRID).astype(int), 0, GRID - 1)
            worst: dict[tuple[int, int], float] = {}
            for (cx, cy), s in zip(cells, sd):
                if s > max_region_sd_px:
                    key = (int(cy), int(cx))
                    worst[key] = max(worst.get(key, 0.0), float(s))
            names = [
                corner_names.get(rc, f"row {rc[0] + 1} col {rc[1] + 1}")
                for rc in sorted(worst, key=lambda k: -worst[k])
            ]
            reasons.append(
                f"the lens is known to {region_sd:.2f} px where the machine's boards are seen "
                f"({region}; need {max_region_sd_px:g} px)"
            )
            advice.append(
                "add views with the board near "
                + ", ".join(names[:6])
                + (" ..." if len(names) > 6 else "")
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
        "; ".join(reasons)
        if reasons
        else f"views pin the lens down where the boards are seen ({region}) and tilt enough",
        "; ".join(advice),
        fraction,
        4 - len(missing),
        max_tilt,
        axes,
        region_sd,
        region,
    )
