"""Line drawings in braille characters: 2 x 4 dots per terminal cell (pure, vectorised).

A terminal cell is about twice as tall as it is wide, so its 2 x 4 dots are square and a
drawing keeps its proportions. :func:`fit` maps a rectangle of the plane onto the dots
(y up); :func:`draw_segments` samples segments onto a dot grid; :func:`cell_bits` packs
the dots of each cell into the braille code point's eight bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

BRAILLE_BLANK = 0x2800
# bit of each dot, by (row within the cell, column within the cell)
DOT_BITS = np.array([[0x01, 0x08], [0x02, 0x10], [0x04, 0x20], [0x40, 0x80]], dtype=np.uint16)
MAX_SAMPLES = 400_000


@dataclass(frozen=True)
class DotFrame:
    """Plane -> dot grid: column = (x - x0) * scale, row counted down from the top."""

    x0: float
    y0: float
    scale: float  # dots per mm
    cols: int  # cells
    rows: int  # cells

    @property
    def width(self) -> int:
        return self.cols * 2

    @property
    def height(self) -> int:
        return self.rows * 4

    def to_dots(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(column, row) dot indices of plane points (may fall outside the grid)."""
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        col = np.floor((p[:, 0] - self.x0) * self.scale).astype(np.int64)
        row = self.height - 1 - np.floor((p[:, 1] - self.y0) * self.scale).astype(np.int64)
        return col, row

    def to_cell(self, x: float, y: float) -> tuple[int, int] | None:
        """(column, row) of the cell holding plane point (x, y); None outside the drawing."""
        col, row = self.to_dots(np.array([[x, y]]))
        c, r = int(col[0]) // 2, int(row[0]) // 4
        return (c, r) if 0 <= c < self.cols and 0 <= r < self.rows else None


def fit(bounds: tuple[float, float, float, float], cols: int, rows: int) -> DotFrame:
    """The frame that shows ``bounds`` (x min, y min, x max, y max) whole and centred in
    ``cols`` x ``rows`` cells, same scale on both axes."""
    cols, rows = max(cols, 1), max(rows, 1)
    x_lo, y_lo, x_hi, y_hi = bounds
    span_x, span_y = max(x_hi - x_lo, 1e-6), max(y_hi - y_lo, 1e-6)
    scale = min((cols * 2 - 1) / span_x, (rows * 4 - 1) / span_y)
    x0 = x_lo - ((cols * 2) / scale - span_x) / 2
    y0 = y_lo - ((rows * 4) / scale - span_y) / 2
    return DotFrame(x0, y0, scale, cols, rows)


def draw_segments(frame: DotFrame, xy0: np.ndarray, xy1: np.ndarray) -> np.ndarray:
    """A (height, width) bool grid with the dots the segments ``xy0[i] -> xy1[i]`` cross."""
    grid = np.zeros((frame.height, frame.width), dtype=bool)
    a = np.asarray(xy0, dtype=float).reshape(-1, 2)
    b = np.asarray(xy1, dtype=float).reshape(-1, 2)
    if len(a) == 0:
        return grid
    length_dots = np.hypot(*(b - a).T) * frame.scale
    n = np.minimum(np.ceil(length_dots * 1.5).astype(np.int64) + 1, 10_000)
    total = int(n.sum())
    if total > MAX_SAMPLES:  # a huge layer: thin the samples evenly, the shape stays
        n = np.maximum((n * (MAX_SAMPLES / total)).astype(np.int64), 1)
        total = int(n.sum())
    owner = np.repeat(np.arange(len(a)), n)
    first = np.cumsum(n) - n
    k = np.arange(total) - np.repeat(first, n)
    t = k / np.maximum(np.repeat(n, n) - 1, 1)
    pts = a[owner] + (b[owner] - a[owner]) * t[:, None]
    col, row = frame.to_dots(pts)
    inside = (col >= 0) & (col < frame.width) & (row >= 0) & (row < frame.height)
    grid[row[inside], col[inside]] = True
    return grid


def cell_bits(grid: np.ndarray) -> np.ndarray:
    """(rows, cols) braille bit masks of a (rows*4, cols*2) dot grid."""
    h, w = grid.shape
    cells = grid.reshape(h // 4, 4, w // 2, 2)
    bits: np.ndarray = np.einsum("rics,is->rc", cells.astype(np.uint16), DOT_BITS)
    return bits.astype(np.uint16)


def braille_char(bits: int) -> str:
    return chr(BRAILLE_BLANK + int(bits))
