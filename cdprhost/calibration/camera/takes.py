"""Camera takes and calibration views as pictures: the shell that reads image folders and
videos and hands the frames to the estimation core (:mod:`cdprhost.calibration.camera`).

A take is a folder of still images (``.png``, ``.jpg``, ``.jpeg``, any case, in natural
name order: ``frame_2`` before ``frame_10``) or one video file (anything
``cv2.VideoCapture`` opens). Every picture must have the size of the camera's
intrinsics, else the take is refused naming the file. :func:`detect_take` finds both
boards in every frame; :func:`session_intrinsics` reads ``camera.toml`` or calibrates
from the session's ``calibration_views``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CameraSetup, CharucoBoard
from cdprhost.calibration.camera.config import CameraConfig, load_intrinsics
from cdprhost.calibration.camera.detection import (
    BoardDetection,
    DetectorSettings,
    detect_board,
    explain_missing_board,
)
from cdprhost.calibration.camera.intrinsics import (
    Intrinsics,
    IntrinsicsResult,
    calibrate_intrinsics,
)
from cdprhost.calibration.camera.session_fit import TakeDetections
from cdprhost.errors import InputError

#: Calibration views without the board that are examined for why (decoding every marker
#: and trying the other layouts costs a few detections each).
EXPLAINED_VIEWS = 3

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def natural_key(name: str) -> tuple[object, ...]:
    """``frame_2`` before ``frame_10``: digit runs compare as numbers."""
    return tuple(int(p) if p.isdigit() else p.lower() for p in re.split(r"(\d+)", name))


def image_files(folder: Path) -> list[Path]:
    """The pictures of a folder, in natural name order (hidden files skipped)."""
    return sorted(
        (
            p
            for p in folder.iterdir()
            if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".")
        ),
        key=lambda p: natural_key(p.name),
    )


@dataclass(frozen=True)
class Frame:
    name: str  # the file (folder takes) or "frame N" (videos)
    image: np.ndarray


def read_frames(
    path: str | os.PathLike[str], image_size: tuple[int, int] | None = None
) -> Iterator[Frame]:
    """The frames of a take (a folder of pictures or a video), checked against
    ``image_size`` (width, height); InputError naming the file otherwise."""
    p = Path(path)
    if p.is_dir():
        files = image_files(p)
        if not files:
            raise InputError(
                f"no pictures in the take folder (expected {', '.join(IMAGE_SUFFIXES)} files)",
                source=str(p),
            )
        for f in files:
            image = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
            if image is None:
                raise InputError("not a picture OpenCV can read", source=str(f))
            _check_size(image, image_size, str(f))
            yield Frame(f.name, image)
        return
    if not p.is_file():
        raise InputError("no such take (expected a folder of pictures or a video)", source=str(p))
    capture = cv2.VideoCapture(str(p))
    try:
        if not capture.isOpened():
            raise InputError("not a video OpenCV can open", source=str(p))
        n = 0
        while True:
            ok, image = capture.read()
            if not ok:
                break
            n += 1
            _check_size(image, image_size, f"{p} (frame {n})")
            yield Frame(f"frame {n}", image)
        if n == 0:
            raise InputError("the video has no frames OpenCV can decode", source=str(p))
    finally:
        capture.release()


def _check_size(image: np.ndarray, size: tuple[int, int] | None, source: str) -> None:
    if size is None:
        return
    h, w = image.shape[:2]
    if (w, h) != tuple(size):
        raise InputError(
            f"picture is {w}x{h} px but the camera's intrinsics are for "
            f"{size[0]}x{size[1]}: every picture must have the calibrated size",
            source=source,
        )


@dataclass(frozen=True, eq=False)
class TakeFrames:
    """A take's detections and the names of its frames (for messages)."""

    detections: TakeDetections
    names: tuple[str, ...]


def detect_take(
    path: str | os.PathLike[str],
    setup: CameraSetup,
    image_size: tuple[int, int] | None = None,
    settings: DetectorSettings | None = None,
    frame_rate_hz: float = 30.0,
) -> TakeFrames:
    """Both boards in every frame of a take."""
    ref: list[BoardDetection | None] = []
    eff: list[BoardDetection | None] = []
    names: list[str] = []
    for frame in read_frames(path, image_size):
        ref.append(detect_board(frame.image, setup.reference.board, settings))
        eff.append(detect_board(frame.image, setup.effector.board, settings))
        names.append(frame.name)
    times = np.arange(len(names)) / frame_rate_hz
    return TakeFrames(TakeDetections(tuple(ref), tuple(eff), times), tuple(names))


def board_missing(frames: TakeFrames, min_corners: int = 6) -> dict[str, list[str]]:
    """Per board ("reference", "effector"), the frames where it is not found well enough."""
    out: dict[str, list[str]] = {"reference": [], "effector": []}
    for name, r, e in zip(frames.names, frames.detections.reference, frames.detections.effector):
        if r is None or len(r) < min_corners:
            out["reference"].append(name)
        if e is None or len(e) < min_corners:
            out["effector"].append(name)
    return out


def calibrate_from_views(
    folder: str | os.PathLike[str],
    board: CharucoBoard,
    settings: DetectorSettings | None = None,
) -> tuple[IntrinsicsResult, tuple[str, ...]]:
    """Intrinsics from a folder (or video) of calibration views; the frames' names."""
    detections: list[BoardDetection | None] = []
    names: list[str] = []
    missing: dict[int, str] = {}
    size: tuple[int, int] | None = None
    for frame in read_frames(folder, size):
        h, w = frame.image.shape[:2]
        size = size or (w, h)
        _check_size(frame.image, size, f"{folder}/{frame.name}")
        found = detect_board(frame.image, board, settings)
        if found is None and len(missing) < EXPLAINED_VIEWS:
            missing[len(detections)] = explain_missing_board(frame.image, board, settings)
        detections.append(found)
        names.append(frame.name)
    if size is None:  # pragma: no cover - read_frames raises first
        raise InputError("no calibration views", source=str(folder))
    try:
        result = calibrate_intrinsics(detections, board, size, missing=missing)
    except ValueError as exc:
        raise InputError(str(exc), source=str(folder)) from None
    return result, tuple(names)


def session_intrinsics(
    root: Path, camera: CameraConfig, settings: DetectorSettings | None = None
) -> tuple[Intrinsics, IntrinsicsResult | None]:
    """The session's intrinsics: its camera.toml, or a calibration from its views (whose
    coverage verdict the caller must honour: the result is returned with it)."""
    from cdprhost.calibration.config_input import contained_path

    rel = camera.intrinsics or camera.calibration_views or ""
    key = "intrinsics" if camera.intrinsics else "calibration_views"
    where = contained_path(root, rel)
    if isinstance(where, str):
        raise InputError(f"[camera] {key}: {where}", source=str(root / "session.toml"))
    if camera.intrinsics:
        return load_intrinsics(where), None
    board = camera.calibration_board
    assert board is not None  # the model's validator guarantees it
    result, _ = calibrate_from_views(where, board.board(), settings)
    return result.intrinsics, result


@dataclass(frozen=True, eq=False)
class CameraTakeCheck:
    """A camera take judged on its own (the wizard, before the session fit)."""

    point: np.ndarray  # mean B of the frames used (base frame, mm)
    spread_mm: float  # RMS distance of the frames' B from it
    n_used: int
    n_frames: int


def skipped_text(names: tuple[str, ...], skipped: tuple[str, ...]) -> str:
    """'the effector board: frame_1.jpg, frame_2.jpg (too few corners); ...', per board."""
    by_board: dict[str, list[str]] = {}
    for name, why in zip(names, skipped):
        if why:
            board = "reference" if "reference" in why else "effector" if "effector" in why else ""
            by_board.setdefault(board or why, []).append(f"{name} ({why})")
    return "; ".join(
        f"{'the ' + b + ' board' if b in ('reference', 'effector') else b} not seen well enough in "
        + ", ".join(frames)
        for b, frames in by_board.items()
    )


def judge_camera_take(
    path: str | os.PathLike[str],
    setup: CameraSetup,
    intrinsics: Intrinsics,
    pose: np.ndarray,
    max_offset_mm: float,
    min_valid_fraction: float = 0.5,
) -> CameraTakeCheck:
    """Detect both boards in every frame and solve B per frame; refuse (TakeRejected,
    naming the board and the frames) when too few frames show both boards well, or when
    the take measures far from the commanded pose."""
    from cdprhost.calibration.camera.positions import effector_positions
    from cdprhost.calibration.takes import TakeRejected

    frames = detect_take(path, setup, intrinsics.image_size)
    d = frames.detections
    fp = effector_positions(list(d.reference), list(d.effector), setup, intrinsics)
    valid = fp.valid & np.isfinite(fp.positions).all(axis=1)
    n = len(frames.names)
    if valid.sum() == 0 or valid.mean() < min_valid_fraction:
        raise TakeRejected(
            f"{int(valid.sum())} of {n} frames usable: {skipped_text(frames.names, fp.skipped)}",
            source=str(path),
            reason="missing-marker",
        )
    pts = fp.positions[valid]
    point = pts.mean(axis=0)
    offset = float(np.linalg.norm(point - np.asarray(pose, float)))
    if offset > max_offset_mm:
        raise TakeRejected(
            f"the effector measures {offset:.1f} mm from the commanded pose; limit "
            f"{max_offset_mm:g} mm: is the effector board's offset right?",
            source=str(path),
            reason="wrong-pose",
        )
    spread = float(np.sqrt(np.mean(np.sum((pts - point) ** 2, axis=1))))
    return CameraTakeCheck(point, spread, int(valid.sum()), n)


@dataclass(frozen=True, eq=False)
class CameraSessionInput:
    """Everything a camera session's pictures give, before any fit: per poses.csv row its
    take's detections (None when unreadable: ``unreadable[row]`` says why), the boards,
    the intrinsics and, when they came from ``calibration_views``, that calibration (whose
    coverage verdict identification must honour)."""

    takes: tuple[TakeFrames | None, ...]
    unreadable: dict[int, str]
    setup: CameraSetup
    intrinsics: Intrinsics
    calibration: IntrinsicsResult | None

    def detections(self) -> list[TakeDetections]:
        """Per row; an unreadable take counts as frames with neither board."""
        empty = TakeDetections((), (), np.zeros(0))
        return [t.detections if t is not None else empty for t in self.takes]


def read_camera_session(
    root: Path,
    camera: CameraConfig,
    take_paths: tuple[Path, ...],
    settings: DetectorSettings | None = None,
) -> CameraSessionInput:
    """Detect both boards in every frame of every take of a camera session."""
    intrinsics, calibration = session_intrinsics(root, camera, settings)
    setup = camera.setup()
    takes: list[TakeFrames | None] = []
    unreadable: dict[int, str] = {}
    for row, path in enumerate(take_paths):
        try:
            takes.append(detect_take(path, setup, intrinsics.image_size, settings))
        except InputError as exc:
            takes.append(None)
            unreadable[row] = str(exc)
    return CameraSessionInput(tuple(takes), unreadable, setup, intrinsics, calibration)
