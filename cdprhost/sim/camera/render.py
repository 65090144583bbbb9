"""Rendering printed ChArUco boards through a distorting lens: the light reaching each pixel.

A board is a textured plane: OpenCV's own board image (``CharucoBoard.generateImage``,
at a texel size matched to how large the board appears, in a white paper margin),
placed in the base frame. For every pixel (supersampled ``s`` x ``s``) the renderer
takes the pixel's ray back through the lens model (:meth:`PinholeCamera.rays`, the
exact inverse of the distortion), intersects it with the board's plane and samples
the texture there; the subsamples are averaged (box filter) into the pixel, so edges
are antialiased and corners sit where the geometry puts them. Boards are drawn far to
near over a background (painter's order), so a near board hides what lies behind it.
Only each board's bounding box in the image is computed; its rays are cached (the
camera does not move). The result is linear radiance in [0, 1]; :mod:`.imaging` turns
it into a picture.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.visibility import sheet_outline
from cdprhost.sim.camera.optics import PinholeCamera

PAPER = 0.85  # reflectance of white paper
INK = 0.04  # of black print
BACK = 0.30  # the back of a board (its plate)
GRID = 8  # px between exactly solved rays (interpolated in between)


@dataclass(frozen=True, eq=False)
class Texture:
    """A board's printed face: reflectance texels; texel (0, 0)'s outer corner sits at
    board coordinates ``(-margin_mm, -margin_mm)``; ``ppm`` texels per mm."""

    image: np.ndarray  # float32 (rows, cols)
    ppm: float
    margin_mm: float

    @property
    def extent_mm(self) -> tuple[float, float]:
        rows, cols = self.image.shape
        return cols / self.ppm, rows / self.ppm


@lru_cache(maxsize=32)
def board_texture(layout: CharucoBoard, px_per_square: int, margin_squares: float = 0.5) -> Texture:
    """The printed face at ``px_per_square`` texels per square, in a white margin."""
    px_per_square = max(int(px_per_square), 24)  # markers need a few texels per bit
    sx, sy = layout.squares
    for _ in range(8):  # OpenCV's generateImage fails for some sizes (a rounding of its ROI)
        try:
            img = layout.cv_board.generateImage(
                (sx * px_per_square, sy * px_per_square), marginSize=0, borderBits=1
            )
            break
        except cv2.error:
            px_per_square += 1
    else:  # pragma: no cover
        raise ValueError(f"OpenCV cannot draw board {layout} at {px_per_square} px per square")
    pad = int(round(margin_squares * px_per_square))
    img = cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)
    refl = (INK + (PAPER - INK) * (img.astype(np.float32) / 255.0)).astype(np.float32)
    ppm = px_per_square / layout.square_mm
    return Texture(refl, ppm, pad / ppm)


@dataclass(frozen=True, eq=False)
class PlacedBoard:
    """A board in the base frame: ``p_base = origin + rotation @ p_board``.

    ``bow_mm`` (along x, along y): how far the middle of the printed chessboard stands
    out of the plane through its edges toward the printed face's side (paper glued on a
    board is never flat): ``z = -(bx (1 - u^2) + by (1 - v^2))`` with ``u, v`` the position
    over the chessboard's half-width and half-height from its middle."""

    layout: CharucoBoard
    rotation: np.ndarray
    origin: np.ndarray
    margin_squares: float = 0.5
    bow_mm: tuple[float, float] = (0.0, 0.0)

    def surface_z(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The printed face's height (board frame z, mm) at board coordinates ``x, y``."""
        return board_bow_z(self.layout, x, y, self.bow_mm)

    def outline(self) -> np.ndarray:
        """The four corners of the printed sheet (with its margin), base frame (4, 3)."""
        return self.origin + sheet_outline(self.layout, self.margin_squares) @ self.rotation.T


def board_bow_z(
    layout: CharucoBoard, x: np.ndarray, y: np.ndarray, bow_mm: tuple[float, float]
) -> np.ndarray:
    """Height of a bowed sheet (see :class:`PlacedBoard`) at board coordinates (mm)."""
    w, h = layout.size_mm
    u = (np.asarray(x, float) - w / 2) / (w / 2)
    v = (np.asarray(y, float) - h / 2) / (h / 2)
    return -(bow_mm[0] * (1.0 - u**2) + bow_mm[1] * (1.0 - v**2))


def _cubic_weights(x: np.ndarray, n: int) -> np.ndarray:
    """(len(x), n) weights of 4-point Lagrange interpolation at fractional indices ``x``."""
    i = np.clip(np.floor(x).astype(int), 1, n - 3)
    t = x - i
    w = np.stack(
        [
            -t * (t - 1) * (t - 2) / 6,
            (t + 1) * (t - 1) * (t - 2) / 2,
            -(t + 1) * t * (t - 2) / 2,
            (t + 1) * t * (t - 1) / 6,
        ],
        axis=1,
    )
    out = np.zeros((len(x), n))
    rows = np.arange(len(x))
    for k in range(4):
        out[rows, i - 1 + k] = w[:, k]
    return out


def _grid(lo: int, hi: int, s: int) -> np.ndarray:
    return lo - 0.5 + (np.arange((hi - lo) * s) + 0.5) / s


class Renderer:
    """Renders boards seen by one (fixed) camera; ``supersample`` per axis."""

    def __init__(
        self,
        camera: PinholeCamera,
        *,
        supersample: int = 2,
        background: np.ndarray | None = None,
        vignetting: float = 0.15,
        seed: int = 0,
    ):
        self.camera = camera
        self.s = int(supersample)
        w, h = camera.image_size
        self.background = background if background is not None else default_background((w, h), seed)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
        self.shading = (1.0 - vignetting * r2).astype(np.float32)
        self._rays: dict[tuple[int, int, int, int], np.ndarray] = {}
        self._grid: np.ndarray | None = None

    def _ray_grid(self) -> np.ndarray:
        """Exact rays on a coarse pixel grid (every ``GRID`` px, one step beyond the image):
        the lens model is smooth, so cubic interpolation of it is exact to ~1e-4 px."""
        if self._grid is None:
            w, h = self.camera.image_size
            u, v = np.meshgrid(
                np.arange(-2, w // GRID + 3) * GRID, np.arange(-2, h // GRID + 3) * GRID
            )
            self._grid = self.camera.rays(u.astype(float), v.astype(float))
        return self._grid

    def _region_rays(self, box: tuple[int, int, int, int]) -> np.ndarray:
        rays = self._rays.get(box)
        if rays is None:
            x0, y0, x1, y1 = box
            grid = self._ray_grid().astype(float)
            wv = _cubic_weights(_grid(y0, y1, self.s) / GRID + 2, grid.shape[0])
            wu = _cubic_weights(_grid(x0, x1, self.s) / GRID + 2, grid.shape[1])
            rays = np.stack([wv @ grid[..., i] @ wu.T for i in range(2)], axis=-1)
            if len(self._rays) > 8:
                self._rays.clear()
            self._rays[box] = rays
        return rays

    def _box(self, board: PlacedBoard) -> tuple[int, int, int, int] | None:
        corners = self.camera.to_camera(board.outline())
        if (corners[:, 2] <= 1.0).any():
            return None
        # sample the outline's edges: distortion bends straight edges
        t = np.linspace(0.0, 1.0, 9)[:, None]
        edges = np.vstack([corners[i] + t * (corners[(i + 1) % 4] - corners[i]) for i in range(4)])
        px = self.camera.project_camera(edges)
        if not np.isfinite(px).all():
            return None
        w, h = self.camera.image_size
        pad = 4
        x0 = max(int(np.floor(px[:, 0].min())) - pad, 0)
        y0 = max(int(np.floor(px[:, 1].min())) - pad, 0)
        x1 = min(int(np.ceil(px[:, 0].max())) + pad, w)
        y1 = min(int(np.ceil(px[:, 1].max())) + pad, h)
        # snap to a coarse grid so frames of one take reuse the cached rays
        x0, y0 = x0 - x0 % 16, y0 - y0 % 16
        x1, y1 = min(x1 + (-x1) % 16, w), min(y1 + (-y1) % 16, h)
        return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None

    def _texels(self, board: PlacedBoard) -> Texture:
        centre = board.outline().mean(axis=0)
        depth = float(self.camera.to_camera(centre)[2])
        px_per_mm = self.camera.matrix[0, 0] / max(depth, 1.0)
        return board_texture(
            board.layout,
            int(np.ceil(board.layout.square_mm * px_per_mm * self.s)),
            float(board.margin_squares),
        )

    def _draw(self, out: np.ndarray, board: PlacedBoard) -> None:
        box = self._box(board)
        if box is None:
            return
        x0, y0, x1, y1 = box
        rays = self._region_rays(box)
        rot = self.camera.rotation @ board.rotation  # board -> camera
        t = self.camera.rotation @ board.origin + self.camera.translation
        n = rot[:, 2]
        denom = rays[..., 0] * n[0] + rays[..., 1] * n[1] + n[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = float(n @ t) / denom
            pts = np.stack([rays[..., 0] * lam, rays[..., 1] * lam, lam], axis=-1) - t
            local = pts @ rot  # R^T (X - t): board coordinates (mm)
            if any(board.bow_mm):
                # the ray meets the bowed face where its local z is the surface's height:
                # z = lam * denom - n.t, so lam = (n.t + z(x, y)) / denom, to a fixed point
                for _ in range(4):
                    lam = (float(n @ t) + board.surface_z(local[..., 0], local[..., 1])) / denom
                    pts = np.stack([rays[..., 0] * lam, rays[..., 1] * lam, lam], axis=-1) - t
                    local = pts @ rot
        tex = self._texels(board)
        cols_mm, rows_mm = tex.extent_mm
        bx = local[..., 0] + tex.margin_mm
        by = local[..., 1] + tex.margin_mm
        cover = (lam > 0) & (bx >= 0) & (bx <= cols_mm) & (by >= 0) & (by <= rows_mm)
        cover &= np.isfinite(lam)
        seen_from = -rot.T @ t  # the camera in board coordinates: the face is at z < 0
        if seen_from[2] < 0:
            mx = np.where(cover, bx * tex.ppm - 0.5, -1).astype(np.float32)
            my = np.where(cover, by * tex.ppm - 0.5, -1).astype(np.float32)
            value = cv2.remap(tex.image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        else:
            value = np.full(cover.shape, BACK, dtype=np.float32)
        s = self.s
        hh, ww = y1 - y0, x1 - x0
        c = cover.astype(np.float32).reshape(hh, s, ww, s).mean(axis=(1, 3))
        v = np.where(cover, value, 0.0).reshape(hh, s, ww, s).mean(axis=(1, 3))
        region = out[y0:y1, x0:x1]
        region *= 1.0 - c
        region += v

    def radiance(self, boards: Sequence[PlacedBoard]) -> np.ndarray:
        """Linear radiance (height, width) float32 of the scene with ``boards``."""
        out = self.background.copy()
        depth = [float(self.camera.to_camera(b.outline().mean(axis=0))[2]) for b in boards]
        for i in np.argsort(depth)[::-1]:
            self._draw(out, boards[int(i)])
        return out * self.shading


def default_background(size: tuple[int, int], seed: int = 0) -> np.ndarray:
    """A dim, blotchy workshop: smooth variation plus fine texture, float32 (height, width)."""
    w, h = size
    rng = np.random.default_rng(seed)
    coarse = rng.uniform(0.15, 0.45, (max(h // 64, 2), max(w // 64, 2))).astype(np.float32)
    img = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    fine = rng.normal(0.0, 0.02, (h, w)).astype(np.float32)
    return np.clip(img + cv2.GaussianBlur(fine, (0, 0), 1.5), 0.02, 0.9)
