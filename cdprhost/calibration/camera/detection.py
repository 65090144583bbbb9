"""Finding a ChArUco board in an image: marker detection, ChArUco interpolation, sub-pixel
corners, and how sharp the image is around them.

Pure: the image comes in as a numpy array (grey or BGR); nothing is read or written.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard

#: A detection with more of its corners failing the chessboard-corner test is checked
#: against the other layout (legacy or not).
MAX_LAYOUT_MISFIT = 0.1


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
    image: np.ndarray,
    board: CharucoBoard,
    settings: DetectorSettings | None = None,
    *,
    check_layout: bool = True,
) -> BoardDetection | None:
    """The board's corners in ``image`` (uint8 grey or BGR), or None when fewer than
    ``settings.min_markers`` markers (or no corner) are found, or when the corners fit
    the other layout (legacy or not) clearly better: every corner one square off."""
    cfg = settings or DetectorSettings()
    grey = _grey(image)
    detector = _detector(board, cfg)
    corners, ids, markers, marker_ids = detector.detectBoard(grey)
    if markers is not None and marker_ids is not None and len(markers) >= 3:
        # a marker elsewhere in the room that decodes as one of the board's ids (a blob in
        # leaves, another board) throws the corners' interpolation off: drop the markers
        # that do not sit where the board's layout puts them, and interpolate again
        keep = markers_on_board(np.asarray(markers, float), marker_ids, board)
        if not keep.all():
            kept = tuple(m for m, k in zip(markers, keep) if k)
            corners, ids, markers, _ = detector.detectBoard(
                grey, markerCorners=kept, markerIds=np.asarray(marker_ids)[keep]
            )
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
    misfit = layout_misfit(grey, board, ids, px)
    if check_layout and misfit > MAX_LAYOUT_MISFIT:
        other = replace(board, legacy_pattern=not board.legacy_pattern)
        alt = detect_board(grey, other, cfg, check_layout=False)
        if (
            alt is not None
            and len(alt) >= 0.8 * ids.size
            and layout_misfit(grey, other, alt.ids, alt.corners_px) < 0.5 * misfit
        ):
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


def layout_misfit(
    grey: np.ndarray, board: CharucoBoard, ids: np.ndarray, corners_px: np.ndarray
) -> float:
    """The fraction of the corners that are not chessboard corners where the layout says.
    A board printed in another layout (OpenCV's legacy pattern) decodes the same markers
    and yields its corners labelled one square off: the row or column of them on the
    board's edge then sits where no inner corner is. An inner corner has like colours in
    opposite quadrants and unlike ones in neighbouring quadrants (sampled in the white rim
    around the markers, through the corners' homography)."""
    if len(ids) < 6:
        return 0.0
    xy = board.corners_mm[ids, :2]
    hom, _ = cv2.findHomography(xy, corners_px, 0)
    if hom is None:
        return 0.0
    d = 0.25 * (board.square_mm - board.marker_mm)  # the middle of a marker's white rim
    offsets = np.array([[d, d], [-d, -d], [d, -d], [-d, d]])
    pts = (xy[:, None, :] + offsets[None]).reshape(-1, 2)
    q = np.c_[pts, np.ones(len(pts))] @ hom.T
    uv = (q[:, :2] / q[:, 2:]).reshape(-1, 4, 2)
    h, w = grey.shape[:2]
    inside = np.all(np.isfinite(uv) & (uv >= 0) & (uv <= [w - 1, h - 1]), axis=(1, 2))
    if inside.sum() < 6:
        return 0.0
    uv = uv[inside]
    img = grey.astype(np.float32)
    vals = img[np.round(uv[..., 1]).astype(int), np.round(uv[..., 0]).astype(int)]
    same = np.abs(vals[:, 0] - vals[:, 1]) + np.abs(vals[:, 2] - vals[:, 3])
    unlike = np.abs(vals[:, :2].mean(axis=1) - vals[:, 2:].mean(axis=1))
    return float(np.mean(unlike <= same))


def explain_missing_board(
    image: np.ndarray, board: CharucoBoard, settings: DetectorSettings | None = None
) -> str:
    """Why ``board`` is not found in ``image``: which markers decode, and whether they fit
    another layout (OpenCV's legacy pattern, the sizes swapped, another first marker id)."""
    cfg = settings or DetectorSettings()
    grey = _grey(image)
    params = _detector(board, cfg).getDetectorParameters()
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    _corners, ids, _ = cv2.aruco.ArucoDetector(dictionary, params).detectMarkers(grey)
    found = np.zeros(0, int) if ids is None else np.asarray(ids, int).ravel()
    if found.size == 0:
        return f"board not found: no {board.dictionary} marker decoded"
    own = np.isin(found, board.marker_ids)
    text = (
        f"board not found: {found.size} {board.dictionary} marker(s) decoded (ids "
        f"{_id_list(found)}), {int(own.sum())} of them the board's ({board.marker_ids[0]}-"
        f"{board.marker_ids[-1]})"
    )
    hints = []
    sx, sy = board.squares
    variants = [
        (board.squares, not board.legacy_pattern, "the legacy layout (OpenCV before 4.6)"),
        ((sy, sx), board.legacy_pattern, f"a {sy}x{sx} board (the sizes swapped)"),
        ((sy, sx), not board.legacy_pattern, f"a {sy}x{sx} board in the legacy layout"),
    ]
    if not own.any():
        start = int(found.min())
        variants.append((board.squares, board.legacy_pattern, f"first_marker_id {start}"))
    for squares, legacy, name in variants:
        first = int(found.min()) if "first_marker_id" in name else board.first_marker_id
        try:
            other = CharucoBoard(
                squares, board.square_mm, board.marker_mm, board.dictionary, first, legacy
            )
        except ValueError:
            continue
        d = detect_board(grey, other, cfg)
        if d is not None and len(d) >= 6:
            hints.append(f"{name}: {len(d)} corners found with it")
    if hints:
        text += (
            "; the markers fit "
            + " and ".join(hints)
            + " (say legacy_pattern = true in the board's table, or ',legacy' in --board)"
        )
    return text


def _id_list(ids: np.ndarray, most: int = 8) -> str:
    u = np.unique(ids)
    shown = ", ".join(str(int(i)) for i in u[:most])
    return shown + (f", ... ({u.size} distinct)" if u.size > most else "")


def markers_on_board(
    markers: np.ndarray, marker_ids: np.ndarray, board: CharucoBoard, tolerance: float = 0.5
) -> np.ndarray:
    """Mask of the decoded ``markers`` ((N, 1, 4, 2) or (N, 4, 2) px, ids (N,)) that sit
    where the board's layout puts them: a homography from each marker's own four corners
    is a hypothesis, the one most other markers agree with (centre within ``tolerance`` x
    their size, then within it of the homography of all that agree) wins. A marker that is
    not the board's, or a second marker with an id already placed, is an impostor."""
    px = np.asarray(markers, float).reshape(-1, 4, 2)
    ids = np.asarray(marker_ids, int).ravel()
    n = len(ids)
    objs = np.asarray(board.cv_board.getObjPoints(), float)[:, :, :2]
    rows = ids - board.first_marker_id
    known = (rows >= 0) & (rows < len(objs))
    keep = known.copy()
    if known.sum() < 3:
        return keep
    obj = np.where(known[:, None, None], objs[np.clip(rows, 0, len(objs) - 1)], 0.0)
    centre_obj = obj.mean(axis=1)
    centre_px = px.mean(axis=1)
    size = np.sqrt(np.abs(_area(px))) + 1e-9

    def agree(hom: np.ndarray) -> np.ndarray:
        q = np.c_[centre_obj, np.ones(n)] @ hom.T
        with np.errstate(divide="ignore", invalid="ignore"):
            err = np.linalg.norm(q[:, :2] / q[:, 2:] - centre_px, axis=1) / size
        return known & np.isfinite(err) & (err <= tolerance)

    best = np.zeros(n, bool)
    for i in np.flatnonzero(known):
        hom = cv2.getPerspectiveTransform(obj[i].astype(np.float32), px[i].astype(np.float32))
        inl = agree(hom)
        if inl.sum() > best.sum():
            best = inl
    for _ in range(2):
        if best.sum() < 2:
            break
        hom, _mask = cv2.findHomography(obj[best].reshape(-1, 2), px[best].reshape(-1, 2), 0)
        if hom is None:
            break
        best = agree(hom)
    if best.sum() < 2:
        return keep
    # one marker per id: a second one with the same id (both agreeing) is ambiguous
    _, first = np.unique(ids[best], return_index=True)
    out = np.zeros(n, bool)
    out[np.flatnonzero(best)[first]] = True
    return out


def _area(quads: np.ndarray) -> np.ndarray:
    x, y = quads[..., 0], quads[..., 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=-1) - np.roll(x, -1, axis=-1) * y, axis=-1)


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
