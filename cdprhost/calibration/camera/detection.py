"""Finding a ChArUco board in an image: marker detection, ChArUco interpolation, sub-pixel
corners, and how sharp the image is around them.

Pure: the image comes in as a numpy array (grey or BGR); nothing is read or written.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard


@dataclass(frozen=True)
class DetectorSettings:
    """Detector tuning. Small markers (about 3 px per bit at 1080p and 0.7 m) need a fine
    adaptive threshold window and a low minimum perimeter."""

    min_marker_perimeter_rate: float = 0.01
    subpix_window: int = 5  # half-size of the sub-pixel refinement window (px)
    min_markers: int = 2
    max_local_misfit_px: float = 0.6  # a corner this far from its neighbours' homography is dropped


@dataclass(frozen=True, eq=False)
class BoardDetection:
    """Chessboard corners of one board found in one image.

    ``ids`` (n,) corner ids of the board (index into ``CharucoBoard.corners_mm``);
    ``corners_px`` (n, 2) sub-pixel positions; ``n_markers`` markers decoded;
    ``sharpness`` a focus measure around the corners (variance of the Laplacian, grey
    levels^2; blur makes it small); ``image_size`` (width, height)."""

    ids: np.ndarray
    corners_px: np.ndarray
    n_markers: int
    sharpness: float
    image_size: tuple[int, int]

    def __len__(self) -> int:
        return int(self.ids.size)


def detect_board(
    image: np.ndarray, board: CharucoBoard, settings: DetectorSettings | None = None
) -> BoardDetection | None:
    """The board's corners in ``image`` (uint8 grey or BGR), or None when fewer than
    ``settings.min_markers`` markers (or no corner) are found."""
    cfg = settings or DetectorSettings()
    grey = _grey(image)
    corners, ids, markers, _ = _detector(board, cfg).detectBoard(grey)
    n_markers = 0 if markers is None else len(markers)
    if ids is None or corners is None or len(ids) == 0 or n_markers < cfg.min_markers:
        return None
    ids = np.asarray(ids, dtype=int).ravel()
    px = refine_corners(grey, np.asarray(corners, dtype=float).reshape(-1, 2), cfg)
    h, w = grey.shape[:2]
    # a corner whose refinement window leaves the image is pulled off: drop it
    margin = 2 * _half_window(px, cfg) + 1
    with np.errstate(invalid="ignore"):
        inside = np.all((px >= margin) & (px <= np.array([w - 1, h - 1]) - margin), axis=1)
    ids, px = ids[inside], px[inside]
    keep = consistent_corners(board.corners_mm[ids, :2], px, cfg.max_local_misfit_px)
    ids, px = ids[keep], px[keep]
    if ids.size == 0:
        return None
    order = np.argsort(ids)
    return BoardDetection(ids[order], px[order], n_markers, sharpness(grey, px), (w, h))


def _grey(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if img.dtype != np.uint8:
        raise ValueError(f"expected an 8-bit image, got {img.dtype}")
    return img


_DETECTORS: dict[tuple[CharucoBoard, DetectorSettings], Any] = {}


def _detector(board: CharucoBoard, cfg: DetectorSettings) -> Any:
    key = (board, cfg)
    if key not in _DETECTORS:
        params = cv2.aruco.DetectorParameters()
        params.minMarkerPerimeterRate = cfg.min_marker_perimeter_rate
        params.adaptiveThreshWinSizeMin = 3
        params.adaptiveThreshWinSizeMax = 33
        params.adaptiveThreshWinSizeStep = 6
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        charuco = cv2.aruco.CharucoParameters()
        charuco.minMarkers = 1
        charuco.tryRefineMarkers = True
        _DETECTORS[key] = cv2.aruco.CharucoDetector(board.cv_board, charuco, params)
    return _DETECTORS[key]


def square_px(corners_px: np.ndarray) -> float:
    """Typical spacing of the corners (px): the median nearest-neighbour distance."""
    if len(corners_px) < 2:
        return float("nan")
    d = np.linalg.norm(corners_px[:, None] - corners_px[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


def consistent_corners(board_xy: np.ndarray, px: np.ndarray, tolerance_px: float) -> np.ndarray:
    """Mask of the corners that their neighbours agree with: each corner is predicted by the
    homography of the corners within 1.5 squares of it on the board (itself left out); a
    corner further than ``tolerance_px`` from that prediction is a mislocated one (the
    detector's guess can lock onto a marker's edge). Corners with fewer than 4 neighbours
    are kept."""
    n = len(px)
    keep = np.ones(n, bool)
    if n < 5:
        return keep
    d = np.linalg.norm(board_xy[:, None] - board_xy[None], axis=2)
    step = np.min(d + np.eye(n) * 1e12)
    for i in range(n):
        near = np.flatnonzero((d[i] <= 1.5 * step + 1e-9) & (np.arange(n) != i))
        if near.size < 4:
            continue
        hom, _ = cv2.findHomography(board_xy[near], px[near], 0)
        if hom is None:
            continue
        q = hom @ np.array([board_xy[i, 0], board_xy[i, 1], 1.0])
        keep[i] = np.linalg.norm(q[:2] / q[2] - px[i]) <= tolerance_px
    return keep


def _half_window(corners_px: np.ndarray, cfg: DetectorSettings) -> int:
    spacing = square_px(corners_px)
    if not np.isfinite(spacing):
        return cfg.subpix_window
    return int(np.clip(round(0.1 * spacing), 2, 8))


def refine_corners(grey: np.ndarray, corners_px: np.ndarray, cfg: DetectorSettings) -> np.ndarray:
    """Sub-pixel corners with a window that suits the squares' size in the image (the
    detector's own window is too wide for small, blurred squares)."""
    half = _half_window(corners_px, cfg)
    pts = corners_px.astype(np.float32).reshape(-1, 1, 2).copy()
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    out = cv2.cornerSubPix(grey, pts, (half, half), (-1, -1), crit).reshape(-1, 2)
    moved = np.linalg.norm(out - corners_px, axis=1)
    # a corner that wandered as far as the window did not converge: NaN (dropped)
    return np.where((moved < half)[:, None], out, np.nan).astype(float)


def sharpness(grey: np.ndarray, corners_px: np.ndarray) -> float:
    """Variance of the Laplacian over the corners' bounding box (blur makes it small)."""
    lo = np.floor(corners_px.min(axis=0)).astype(int)
    hi = np.ceil(corners_px.max(axis=0)).astype(int) + 1
    h, w = grey.shape[:2]
    x0, y0 = max(lo[0], 0), max(lo[1], 0)
    x1, y1 = min(hi[0], w), min(hi[1], h)
    if x1 - x0 < 3 or y1 - y0 < 3:
        return 0.0
    lap = cv2.Laplacian(grey[y0:y1, x0:x1], cv2.CV_64F)
    return float(lap.var())
