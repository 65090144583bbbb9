"""A minimal ChArUco renderer for the estimation tests (the product's simulated camera is
cdprhost/sim): each board drawn by a homography of its generated image, then lens
distortion, blur, noise and JPEG."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.intrinsics import Intrinsics

_CACHE: dict[CharucoBoard, tuple[np.ndarray, float]] = {}
SQUARE_PX = 128


def _board_image(board: CharucoBoard) -> tuple[np.ndarray, float]:
    """The board drawn exactly (every square SQUARE_PX wide) and its pixels per mm
    (OpenCV's generateImage rounds square edges by a pixel)."""
    if board in _CACHE:
        return _CACHE[board]
    sx, sy = board.squares
    p = SQUARE_PX
    scale = p / board.square_mm
    img = np.zeros((sy * p, sx * p), np.uint8)
    cvb = board.cv_board
    objs = [np.asarray(o, float).reshape(4, 3) for o in cvb.getObjPoints()]
    ids = np.asarray(cvb.getIds()).ravel()
    dictionary = cvb.getDictionary()
    m_px = round(board.marker_mm * scale)
    for o, marker in zip(objs, ids):
        i, j = (o[:, :2].mean(axis=0) // board.square_mm).astype(int)
        img[j * p : (j + 1) * p, i * p : (i + 1) * p] = 255
        x0 = i * p + (p - m_px) // 2
        y0 = j * p + (p - m_px) // 2
        img[y0 : y0 + m_px, x0 : x0 + m_px] = dictionary.generateImageMarker(int(marker), m_px, 1)
    _CACHE[board] = (img, scale)
    return img, scale


def render(
    boards: Sequence[tuple[CharucoBoard, np.ndarray, np.ndarray]],
    intr: Intrinsics,
    *,
    blur_px: float = 0.0,
    noise: float = 0.0,
    jpeg: int | None = None,
    rng: np.random.Generator | None = None,
    background: int = 110,
    contrast: float = 1.0,
) -> np.ndarray:
    """An 8-bit grey image of ``boards`` (board, R board->camera, t mm)."""
    w, h = intr.image_size
    pad = max(w, h) // 4  # the ideal image reaches beyond the frame that barrel distortion shows
    k = np.asarray(intr.matrix, float)
    shift = np.array([[1.0, 0, pad], [0, 1.0, pad], [0, 0, 1]])
    acc = np.full((h + 2 * pad, w + 2 * pad), float(background))
    for board, rot, t in boards:
        raw, px_per_mm = _board_image(board)
        img = raw.astype(float)
        s = 1.0 / px_per_mm
        # board image pixel centre (u + 0.5, v + 0.5) -> board mm (x, y, 0)
        to_mm = np.array([[s, 0, 0.5 * s], [0, s, 0.5 * s], [0, 0, 1]])
        hom = shift @ k @ np.column_stack([rot[:, 0], rot[:, 1], t]) @ to_mm
        # anti-alias: low-pass the board image to the resolution it lands at
        depth = float(np.mean(t[2] + 0.0))
        src_per_dst = px_per_mm * depth / float(k[0, 0])
        if src_per_dst > 1:
            img = cv2.GaussianBlur(img, (0, 0), 0.5 * src_per_dst)
        warped = cv2.warpPerspective(
            img, hom, (w + 2 * pad, h + 2 * pad), flags=cv2.INTER_LINEAR, borderValue=-1
        )
        mask = cv2.warpPerspective(
            np.ones_like(img),
            hom,
            (w + 2 * pad, h + 2 * pad),
            flags=cv2.INTER_LINEAR,
            borderValue=0,
        )
        acc = np.where(mask > 0.5, background + contrast * (warped - background), acc)
    dist = intr.distortion_5
    if np.any(dist != 0):
        uu, vv = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        pts = np.stack([uu.ravel(), vv.ravel()], axis=1)[:, None, :]
        ideal = cv2.undistortPointsIter(
            pts, k, dist, None, k, (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-6)
        ).reshape(h, w, 2)
        acc = cv2.remap(
            acc.astype(np.float32), ideal[..., 0] + pad, ideal[..., 1] + pad, cv2.INTER_LINEAR
        ).astype(float)
    else:
        acc = acc[pad : pad + h, pad : pad + w]
    if blur_px > 0:
        acc = cv2.GaussianBlur(acc, (0, 0), blur_px)
    if noise > 0:
        acc = acc + (rng or np.random.default_rng()).normal(0, noise, acc.shape)
    out = np.clip(np.rint(acc), 0, 255).astype(np.uint8)
    if jpeg is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, jpeg])
        out = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    return out


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """world -> camera (R, t) of a camera at ``eye`` looking at ``target`` (z forward, y down)."""
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, up)
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    rot = np.stack([x, y, z])
    return rot, -rot @ eye
