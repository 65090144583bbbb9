"""Takes from a live camera for the wizard: capture, live board status, the first look.

A capture is anything with ``cv2.VideoCapture``'s ``isOpened``/``read``/``release``: a
device index, a file or a URL (:func:`open_capture`), or the simulated camera.
:class:`CameraTakes` is the wizard's take source: at each settled pose it drops a few
stale frames, captures ``frames`` pictures into a take folder and logs each board's
status (corners found, sharpness, reprojection error). :meth:`CameraTakes.first_look`
is the check before the first move: both boards must be seen, and the picture gives the
camera's pose and the effector board's orientation for pose planning
(:mod:`.camera.visibility`).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CameraSetup, CharucoBoard
from cdprhost.calibration.camera.detection import BoardDetection, detect_board
from cdprhost.calibration.camera.intrinsics import Intrinsics
from cdprhost.calibration.camera.pose import BoardPose, solve_board_pose
from cdprhost.calibration.camera.visibility import CameraView, view_from_poses
from cdprhost.errors import InputError


class Capture(Protocol):
    def isOpened(self) -> bool: ...
    def read(self) -> tuple[bool, Any]: ...
    def release(self) -> None: ...


def open_capture(spec: str) -> Capture:
    """A device index (``0``), a video file or a URL, opened with ``cv2.VideoCapture``."""
    source: int | str = int(spec) if spec.strip().isdigit() else spec
    capture = cv2.VideoCapture(source)
    if not capture.isOpened():
        raise InputError(f"cannot open camera {spec!r} (a device index, a video file or a URL)")
    return capture


@dataclass(frozen=True, eq=False)
class BoardStatus:
    """One board in one picture: what the live view shows."""

    name: str
    detection: BoardDetection | None
    total_corners: int
    pose: BoardPose | None

    @property
    def seen(self) -> bool:
        return self.pose is not None

    def text(self) -> str:
        d = self.detection
        if d is None:
            return f"{self.name} board: not found"
        reproj = f"{self.pose.rms_px:.2f} px" if self.pose is not None else "no pose"
        return (
            f"{self.name} board: {len(d)}/{self.total_corners} corners, "
            f"sharpness {d.sharpness:.0f}, reprojection {reproj}"
        )


def board_status(
    image: np.ndarray, name: str, board: CharucoBoard, intrinsics: Intrinsics, min_corners: int = 6
) -> BoardStatus:
    det = detect_board(image, board)
    pose = (
        solve_board_pose(det, board, intrinsics)
        if det is not None and len(det) >= min_corners
        else None
    )
    return BoardStatus(name, det, len(board.corners_mm), pose)


@dataclass
class CameraTakes:
    """The wizard's take source for a live camera: ``frames`` pictures per take, written
    as JPEG into ``folder/pose_NN_try_M/``."""

    capture: Capture
    folder: Path
    setup: CameraSetup
    intrinsics: Intrinsics
    frames: int = 5
    discard: int = 2
    log: Callable[[str], None] = print

    def grab(self) -> np.ndarray:
        ok, image = self.capture.read()
        if not ok or image is None:
            raise InputError("the camera gave no picture (disconnected, or the end of a video?)")
        h, w = image.shape[:2]
        if (w, h) != tuple(self.intrinsics.image_size):
            raise InputError(
                f"the camera gives {w}x{h} px pictures but its intrinsics are for "
                f"{self.intrinsics.image_size[0]}x{self.intrinsics.image_size[1]}"
            )
        return np.asarray(image)

    def status(self, image: np.ndarray) -> tuple[BoardStatus, BoardStatus]:
        return (
            board_status(image, "reference", self.setup.reference.board, self.intrinsics),
            board_status(image, "effector", self.setup.effector.board, self.intrinsics),
        )

    def first_look(self) -> CameraView:
        """Both boards must be seen before anything moves; returns what planning needs."""
        ref, eff = self.status(self.grab())
        self.log(f"camera: {ref.text()}; {eff.text()}")
        missing = [s.name for s in (ref, eff) if not s.seen]
        if missing or ref.pose is None or eff.pose is None:
            raise InputError(
                f"the camera does not see the {' and the '.join(missing)} board well enough "
                "before the first move: check the view, focus and light, then start again"
            )
        return view_from_poses(ref.pose, eff.pose, self.setup, self.intrinsics)

    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        for _ in range(self.discard):  # frames buffered while the machine moved
            self.grab()
        images = [self.grab() for _ in range(self.frames)]
        out = self.folder / f"pose_{index + 1:02d}_try_{attempt + 1}"
        tmp = out.with_name(out.name + ".tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        for n, image in enumerate(images, start=1):
            cv2.imwrite(str(tmp / f"frame_{n}.jpg"), image, [cv2.IMWRITE_JPEG_QUALITY, 95])
        shutil.rmtree(out, ignore_errors=True)
        tmp.rename(out)
        ref, eff = self.status(images[-1])
        self.log(f"  live: {ref.text()}; {eff.text()}")
        return out


def collect_views(
    capture: Capture,
    board: CharucoBoard,
    n_views: int,
    *,
    max_frames: int | None = None,
    min_move: float = 0.04,
    min_corners: int = 8,
    log: Callable[[str], None] = print,
) -> tuple[list[BoardDetection | None], list[np.ndarray]]:
    """Calibration views from a live camera while the user moves the board: a picture is
    kept when the board is found with ``min_corners`` and has moved (mean corner shift of
    ``min_move`` x the image width) from every view kept so far."""
    kept: list[BoardDetection | None] = []
    images: list[np.ndarray] = []
    limit = max_frames if max_frames is not None else 40 * n_views
    for _ in range(limit):
        ok, image = capture.read()
        if not ok or image is None:
            break
        det = detect_board(image, board)
        if det is None or len(det) < min_corners:
            continue
        w = image.shape[1]
        if any(_shift(det, k) < min_move * w for k in kept if k is not None):
            continue
        kept.append(det)
        images.append(np.asarray(image))
        log(f"view {len(kept)}/{n_views}: {len(det)} corners, sharpness {det.sharpness:.0f}")
        if len(kept) >= n_views:
            break
    return kept, images


def _shift(a: BoardDetection, b: BoardDetection) -> float:
    common, ia, ib = np.intersect1d(a.ids, b.ids, return_indices=True)
    if common.size < 4:
        return float("inf")
    return float(np.mean(np.linalg.norm(a.corners_px[ia] - b.corners_px[ib], axis=1)))
