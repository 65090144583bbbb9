"""Whole camera session folders (camera-session.md) rendered from a true machine.

:func:`write_camera_session` commands ``poses`` through the ``nominal`` model (as the host
does), finds where the ``truth`` machine really puts ``B`` (its geometry and effects, e.g.
``drive_scale``), and renders each take as the rig's camera sees it: ``frames_per_take``
pictures (a folder of JPEG/PNG files, or one MJPG video). The intrinsics the session
carries are, by default, calibrated from rendered calibration views (``"calibrated"``,
what a user gets, not the truth), or the truth (``"truth"``), or given (an
``Intrinsics``: a calibration made before), or the views themselves are stored for the
reader to calibrate (``"views"``). ``take_imaging`` overrides the
imaging of chosen takes (heavy blur, low light), ``occluders`` hide parts of chosen takes.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from cdprhost.calibration.camera.boards import CharucoBoard
from cdprhost.calibration.camera.config import CAMERA_FILE, CameraConfig, intrinsics_toml
from cdprhost.calibration.camera.detection import detect_board
from cdprhost.calibration.camera.intrinsics import (
    Intrinsics,
    IntrinsicsResult,
    calibrate_intrinsics,
)
from cdprhost.calibration.commanding import commanded_path
from cdprhost.calibration.poses import POSE_COLUMNS
from cdprhost.calibration.session import POSES_FILE, SESSION_FILE, SessionConfig
from cdprhost.calibration.session_writer import session_toml
from cdprhost.effects.base import MotionContext
from cdprhost.fileio.atomic import write_text_atomic
from cdprhost.kinematics.machine import MachineModel
from cdprhost.sim.camera.imaging import Imaging, decode
from cdprhost.sim.camera.scene import CALIBRATION_BOARD, CameraRig
from cdprhost.sim.camera.views import Coverage, render_views

VIEWS_DIR = "intrinsics"
IntrinsicsSource = Literal["calibrated", "truth", "views"]


def camera_config(
    rig: CameraRig, intrinsics: IntrinsicsSource = "calibrated", **acceptance: float
) -> CameraConfig:
    """The ``[camera]`` section describing ``rig`` (boards as set up; the effector board's
    true orientation is not in it: the reader finds it)."""
    ref, eff = rig.setup.reference, rig.setup.effector

    def board(b: CharucoBoard) -> dict[str, object]:
        return {
            "dictionary": b.dictionary,
            "squares": list(b.squares),
            "square_mm": b.square_mm,
            "marker_mm": b.marker_mm,
            "first_marker_id": b.first_marker_id,
        }

    data: dict[str, object] = {
        "reference_board": {
            **board(ref.board),
            "origin": list(ref.origin),
            "rotation_deg": list(ref.rotation_deg),
        },
        "effector_board": {**board(eff.board), "offset": list(eff.offset)},
    }
    if intrinsics == "views":
        data["calibration_views"] = VIEWS_DIR
        data["calibration_board"] = board(CALIBRATION_BOARD)
    else:
        data["intrinsics"] = CAMERA_FILE
    if acceptance:
        data["acceptance"] = dict(acceptance)
    return CameraConfig.model_validate(data)


def true_intrinsics(rig: CameraRig) -> Intrinsics:
    cam = rig.camera
    return Intrinsics(np.asarray(cam.matrix), np.asarray(cam.distortion), cam.image_size)


def calibrated_intrinsics(
    rig: CameraRig,
    n_views: int = 18,
    seed: int = 0,
    supersample: int = 2,
    *,
    views_kind: Coverage = "good",
    bow_mm: tuple[float, float] = (0.0, 0.0),
) -> IntrinsicsResult:
    """What a user's calibration of the rig's camera gives: rendered views of the
    calibration board (``views_kind``, the sheet bowed by ``bow_mm``), detected and
    calibrated by the product's own code."""
    cam = rig.camera
    views = render_views(
        cam,
        rig.imaging,
        CALIBRATION_BOARD,
        n_views,
        views_kind,
        seed=seed,
        supersample=supersample,
        bow_mm=bow_mm,
    )
    detections = [detect_board(decode(v), CALIBRATION_BOARD) for v in views]
    return calibrate_intrinsics(detections, CALIBRATION_BOARD, cam.image_size)


def write_views(
    folder: str | os.PathLike[str],
    rig: CameraRig,
    n_views: int = 18,
    coverage: Coverage = "good",
    seed: int = 0,
    supersample: int = 2,
    *,
    bow_mm: tuple[float, float] = (0.0, 0.0),
) -> Path:
    """A folder of calibration views (``view_01.jpg``, ...)."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    views = render_views(
        rig.camera,
        rig.imaging,
        CALIBRATION_BOARD,
        n_views,
        coverage,
        seed,
        supersample,
        bow_mm=bow_mm,
    )
    for i, data in enumerate(views, start=1):
        (out / f"view_{i:02d}{rig.imaging.extension}").write_bytes(data)
    return out


@dataclass(frozen=True, eq=False)
class CameraSession:
    directory: Path
    actual: np.ndarray  # (K, 3) where B truly was at each pose (base frame, mm)
    s_cmd: np.ndarray  # (K, 3)
    rig: CameraRig
    intrinsics: Intrinsics  # what the session's camera.toml says (or the truth, for "views")
    calibration: IntrinsicsResult | None


def _write_video(path: Path, frames: list[bytes], fps: float = 30.0) -> None:
    images = [decode(f) for f in frames]
    h, w = images[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (w, h))
    try:
        for img in images:
            writer.write(img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    finally:
        writer.release()


def write_camera_session(
    directory: str | os.PathLike[str],
    truth: MachineModel,
    nominal: MachineModel,
    poses: np.ndarray,
    *,
    rig: CameraRig,
    t_s: np.ndarray | None = None,
    frames_per_take: int = 4,
    take_kind: Literal["images", "video"] = "images",
    intrinsics: IntrinsicsSource | Intrinsics = "calibrated",
    n_views: int = 18,
    views_kind: Coverage = "good",
    bow_mm: tuple[float, float] = (0.0, 0.0),
    profile_name: str = "paper-simulation",
    roles: Sequence[str] | None = None,
    jitter_mm: float = 0.003,
    take_imaging: Mapping[int, Imaging] | None = None,
    occluders: Mapping[int, Sequence[np.ndarray]] | None = None,
    take_creep_mm: Mapping[int, Sequence[float]] | None = None,
    take_shake_mm: Mapping[int, float] | None = None,
    supersample: int = 2,
    seed: int = 0,
) -> CameraSession:
    """A camera session folder for ``poses`` (visiting order) on the ``truth`` machine.
    ``views_kind``/``bow_mm``: the calibration views (``"printed"``: a user's bowed sheet,
    see :mod:`.views`).
    ``take_imaging``/``occluders``/``take_creep_mm``/``take_shake_mm`` are keyed by pose
    number (from 1); a creeping take's effector moves steadily by that vector (mm) from its
    first frame to its last; a shaking take's effector is displaced in every frame by an
    independent random vector of that RMS (mm) per coordinate."""
    root = Path(directory)
    (root / "takes").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    pts = np.asarray(poses, dtype=float).reshape(-1, 3)
    k = len(pts)
    times = np.arange(1, k + 1) * 30.0 if t_s is None else np.asarray(t_s, float).reshape(k)
    s_cmd, dirs = commanded_path(nominal, pts)
    actual = truth.fk(s_cmd, MotionContext(t_s=times, directions=dirs))

    calibration: IntrinsicsResult | None = None
    used = true_intrinsics(rig)
    if isinstance(intrinsics, Intrinsics):  # a calibration made before (benchmarks)
        used, intrinsics = intrinsics, "calibrated"
    elif intrinsics == "calibrated":
        calibration = calibrated_intrinsics(
            rig, n_views, seed, supersample, views_kind=views_kind, bow_mm=bow_mm
        )
        used = calibration.intrinsics
    if intrinsics == "views":
        write_views(
            root / VIEWS_DIR,
            rig,
            n_views,
            views_kind,
            seed=seed,
            supersample=supersample,
            bow_mm=bow_mm,
        )
    else:
        write_text_atomic(root / CAMERA_FILE, intrinsics_toml(used))
    config = SessionConfig.model_validate(
        {"session": {"profile": profile_name}, "camera": camera_config(rig, intrinsics)}
    )
    write_text_atomic(root / SESSION_FILE, session_toml(config))

    renderer = rig.renderer(supersample, seed)
    header = [*POSE_COLUMNS, "role"]
    buf = io.StringIO()
    table = csv.writer(buf, lineterminator="\n")
    table.writerow(header)
    for i in range(k):
        number = i + 1
        take_rig = rig if not take_imaging or number not in take_imaging else None
        if take_rig is None:
            take_rig = CameraRig(
                rig.camera, rig.setup, rig.effector_rotation, (take_imaging or {})[number]
            )
        hide = (occluders or {}).get(number, ())
        creep = np.asarray((take_creep_mm or {}).get(number, (0.0, 0.0, 0.0)), float)
        ramp = np.linspace(-0.5, 0.5, frames_per_take) if frames_per_take > 1 else np.zeros(1)
        shake = float((take_shake_mm or {}).get(number, 0.0))
        frames = [
            take_rig.frame(
                renderer,
                actual[i]
                + r * creep
                + rng.normal(0.0, jitter_mm, 3)
                + (rng.normal(0.0, shake, 3) if shake > 0 else 0.0),
                rng,
                hide,
            )
            for r in ramp
        ]
        if take_kind == "video":
            rel = f"takes/pose_{number:04d}.avi"
            _write_video(root / rel, frames)
        else:
            rel = f"takes/pose_{number:04d}"
            (root / rel).mkdir(exist_ok=True)
            for j, data in enumerate(frames, start=1):
                (root / rel / f"frame_{j}{take_rig.imaging.extension}").write_bytes(data)
        role = "fit" if roles is None else roles[i]
        table.writerow(
            [number, rel, f"{times[i]:.3f}"]
            + [f"{v:.6f}" for v in pts[i]]
            + [f"{v:.6f}" for v in s_cmd[i]]
            + [str(int(d)) for d in dirs[i]]
            + [role]
        )
    write_text_atomic(root / POSES_FILE, buf.getvalue())
    return CameraSession(root, actual, s_cmd, rig, used, calibration)
