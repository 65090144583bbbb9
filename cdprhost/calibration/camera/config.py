"""The ``[camera]`` section of session.toml and the ``camera.toml`` intrinsics file
(camera-session.md), validated at the boundary.

:class:`CameraConfig` holds the intrinsics source (``intrinsics`` = a camera.toml, or
``calibration_views`` = a folder of pictures of ``[camera.calibration_board]``), the
two boards and the take thresholds (``[camera.acceptance]``: the keys of
``[mocap.acceptance]``, plus ``accuracy_mm``). :meth:`CameraConfig.setup` gives the
estimation core's :class:`~cdprhost.calibration.camera.boards.CameraSetup`.
:func:`load_intrinsics` reads camera.toml into
:class:`~cdprhost.calibration.camera.intrinsics.Intrinsics` and :func:`intrinsics_toml`
writes one (with each parameter's standard deviation, when known).
"""

from __future__ import annotations

import math
import os
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from cdprhost.calibration.acceptance import AcceptanceLimits
from cdprhost.calibration.camera.boards import (
    CameraSetup,
    CharucoBoard,
    EffectorBoard,
    ReferenceBoard,
)
from cdprhost.calibration.camera.intrinsics import PARAMETER_NAMES, Intrinsics
from cdprhost.errors import InputError

Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]
CAMERA_FILE = "camera.toml"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class BoardConfig(_Strict):
    """A ``[camera.*_board]`` table: the printed ChArUco board."""

    dictionary: str = "DICT_5X5_250"
    squares: tuple[Annotated[int, Field(ge=2)], Annotated[int, Field(ge=2)]]
    square_mm: float = Field(gt=0)
    marker_mm: float = Field(gt=0)
    first_marker_id: int = Field(default=0, ge=0)
    legacy_pattern: bool = False

    @model_validator(mode="after")
    def _buildable(self) -> BoardConfig:
        self.board()  # a ValueError names what is wrong (marker size, dictionary)
        return self

    def board(self) -> CharucoBoard:
        return CharucoBoard(
            (int(self.squares[0]), int(self.squares[1])),
            float(self.square_mm),
            float(self.marker_mm),
            self.dictionary,
            int(self.first_marker_id),
            bool(self.legacy_pattern),
        )


class ReferenceBoardConfig(BoardConfig):
    origin: Vec3
    rotation_deg: Vec3 = (180.0, 0.0, 0.0)


class EffectorBoardConfig(BoardConfig):
    offset: Vec3
    offset_sigma_mm: float = Field(default=0.0, ge=0)


class CameraAcceptance(AcceptanceLimits):
    """``[camera.acceptance]``: the take thresholds of ``[mocap.acceptance]``, and the
    camera's per-place accuracy when known."""

    accuracy_mm: float | None = Field(default=None, gt=0)


class CameraConfig(_Strict):
    """``[camera]`` of session.toml."""

    intrinsics: str | None = None
    calibration_views: str | None = None
    reference_board: ReferenceBoardConfig
    effector_board: EffectorBoardConfig
    calibration_board: BoardConfig | None = None
    acceptance: CameraAcceptance = CameraAcceptance()

    @model_validator(mode="after")
    def _one_source(self) -> CameraConfig:
        if (self.intrinsics is None) == (self.calibration_views is None):
            raise ValueError(
                "give exactly one of intrinsics (a camera.toml) and calibration_views "
                "(a folder of pictures of [camera.calibration_board])"
            )
        if self.calibration_views is not None and self.calibration_board is None:
            raise ValueError("calibration_views needs a [camera.calibration_board] table")
        self.setup()  # disjoint marker ids
        return self

    def setup(self) -> CameraSetup:
        ref, eff = self.reference_board, self.effector_board
        return CameraSetup(
            ReferenceBoard(ref.board(), ref.origin, ref.rotation_deg),
            EffectorBoard(eff.board(), eff.offset, eff.offset_sigma_mm),
        )


class CameraFileModel(_Strict):
    """``[camera]`` of camera.toml."""

    image_size: tuple[Annotated[int, Field(gt=0)], Annotated[int, Field(gt=0)]]
    matrix: tuple[Vec3, Vec3, Vec3]
    distortion: tuple[Finite, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    rms_reprojection_px: float | None = Field(default=None, ge=0)
    std: dict[str, float] | None = None  # per parameter (fx, fy, cx, cy, k1, ...), optional

    @model_validator(mode="after")
    def _sane(self) -> CameraFileModel:
        k = np.asarray(self.matrix, dtype=float)
        if not (k[0, 0] > 0 and k[1, 1] > 0):
            raise ValueError("matrix: the focal lengths (matrix[0][0], matrix[1][1]) must be > 0")
        if k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1:
            raise ValueError("matrix: must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
        if len(self.distortion) not in (4, 5):
            raise ValueError(
                f"distortion: expected 5 values k1, k2, p1, p2, k3 (or 4), got {len(self.distortion)}"
            )
        unknown = sorted(set(self.std or {}) - set(PARAMETER_NAMES))
        if unknown:
            raise ValueError(
                f"std: unknown parameter(s) {', '.join(unknown)} (known: {', '.join(PARAMETER_NAMES)})"
            )
        return self

    def intrinsics(self) -> Intrinsics:
        d = np.zeros(5)
        d[: len(self.distortion)] = self.distortion
        std = np.array([(self.std or {}).get(n, math.nan) for n in PARAMETER_NAMES])
        return Intrinsics(
            np.asarray(self.matrix, dtype=float),
            d,
            (int(self.image_size[0]), int(self.image_size[1])),
            std,
            self.rms_reprojection_px,
        )


def load_intrinsics(path: str | os.PathLike[str]) -> Intrinsics:
    """camera.toml -> Intrinsics; errors name the file and the key."""
    from cdprhost.calibration.config_input import read_toml, validation_problems

    src = str(path)
    data = read_toml(path)
    if "camera" not in data:
        raise InputError("no [camera] table (image_size, matrix, distortion)", source=src)
    try:
        return CameraFileModel.model_validate(data["camera"]).intrinsics()
    except ValidationError as exc:
        raise InputError(
            "invalid camera intrinsics", source=src, problems=validation_problems(exc, "camera")
        ) from None


def load_camera_config(path: str | os.PathLike[str]) -> CameraConfig:
    """The ``[camera]`` table of a TOML file (a session.toml or just that table): the boards;
    errors name the file and the key."""
    from cdprhost.calibration.config_input import read_toml, validation_problems

    src = str(path)
    data = read_toml(path)
    if "camera" not in data:
        raise InputError("no [camera] table (the boards of camera-session.md)", source=src)
    try:
        return CameraConfig.model_validate(data["camera"])
    except ValidationError as exc:
        raise InputError(
            "invalid [camera] table", source=src, problems=validation_problems(exc, "camera")
        ) from None


def intrinsics_toml(intrinsics: Intrinsics, extra: dict[str, Any] | None = None) -> str:
    """camera.toml text for ``intrinsics`` (``std`` where known; ``extra`` keys in [camera])."""
    import tomli_w

    k = np.asarray(intrinsics.matrix, dtype=float)
    table: dict[str, Any] = {
        "image_size": [int(v) for v in intrinsics.image_size],
        "matrix": [[float(v) for v in row] for row in k],
        "distortion": [float(v) for v in intrinsics.distortion_5],
    }
    if intrinsics.rms_reprojection_px is not None:
        table["rms_reprojection_px"] = float(intrinsics.rms_reprojection_px)
    std = {n: float(s) for n, s in zip(PARAMETER_NAMES, intrinsics.std) if np.isfinite(s)}
    if std:
        table["std"] = std
    table.update(extra or {})
    return tomli_w.dumps({"camera": table})
