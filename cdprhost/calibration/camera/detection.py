"""Finding a ChArUco board in an image: marker detection, ChArUco interpolation, sub-pixel
corners, and how sharp the image is around them.

Pure: the image comes in as a numpy array (grey or BGR); nothing is read or written.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard


@dataclass(frozen=True)
class DetectorSettings:
    """Detector tuning. Small markers (about 3 px per bit at 1080p and 0.7 m) need a fine
    adaptive threshold window and a low minimum perimeter."""

    min_marker_perimeter_rate: float = 0.01
    subpix_window: int = 5  # half-size of the sub-pixel refinement window (px)
    min_markers: int = 2


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
    raise NotImplementedError
