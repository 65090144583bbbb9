"""Writing a calibration session folder: ``session.toml`` text and :class:`SessionWriter`,
which creates or resumes a folder one pose at a time, crash-safely."""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cdprhost.calibration.acceptance import AcceptanceLimits
from cdprhost.calibration.mocap.readers import EXTENSIONS, Take, write_take
from cdprhost.calibration.poses import POSE_COLUMNS, parse_poses
from cdprhost.calibration.session import (
    POSES_FILE,
    SESSION_FILE,
    TAKES_DIR,
    SessionConfig,
    load_session_config,
)
from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic


def _toml_value(v: Any) -> str:
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # a JSON string is a valid TOML basic string
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to session.toml")


def session_toml(config: SessionConfig) -> str:
    """session.toml text for ``config`` (the layout of the spec; default limits omitted)."""
    import tomli_w

    out = ["[session]"] + [
        f"{k} = {_toml_value(v)}" for k, v in config.session.model_dump().items() if v is not None
    ]
    extra = {
        k: v
        for k, v in config.model_dump(exclude_none=True).items()
        if k not in ("session", "mocap", "camera")
    }
    if config.camera is not None:
        cam = config.camera
        tables: dict[str, dict[str, Any]] = {
            "camera": cam.model_dump(
                exclude_none=True,
                include={"intrinsics", "calibration_views"},
            ),
            "camera.reference_board": cam.reference_board.model_dump(),
            "camera.effector_board": cam.effector_board.model_dump(),
        }
        if cam.calibration_board is not None:
            tables["camera.calibration_board"] = cam.calibration_board.model_dump()
        acceptance = cam.acceptance.model_dump(exclude_defaults=True, exclude_none=True)
        if acceptance:
            tables["camera.acceptance"] = acceptance
        for name, table in tables.items():
            out += ["", f"[{name}]"] + [f"{k} = {_toml_value(v)}" for k, v in table.items()]
        text = "\n".join(out) + "\n"
        return text + ("\n" + tomli_w.dumps(extra) if extra else "")
    mocap = config.motion_capture
    out += ["", "[mocap]"]
    if mocap.format is not None:
        out.append(f"format = {_toml_value(mocap.format)}")
    if mocap.noise_mm is not None:
        out.append(f"noise_mm = {_toml_value(mocap.noise_mm)}")
    out += ["", "[mocap.base_markers]"]
    out += [f"{_toml_value(k)} = {_toml_value(list(v))}" for k, v in mocap.base_markers.items()]
    out += [
        "",
        "[mocap.effector]",
        f"markers = {_toml_value(list(mocap.effector.markers))}",
        f"offset = {_toml_value(list(mocap.effector.offset))}",
    ]
    if mocap.acceptance != AcceptanceLimits():
        out += ["", "[mocap.acceptance]"] + [
            f"{k} = {_toml_value(v)}" for k, v in mocap.acceptance.model_dump().items()
        ]
    text = "\n".join(out) + "\n"
    return text + ("\n" + tomli_w.dumps(extra) if extra else "")


def _fmt(v: float) -> str:
    return f"{v:.6f}".rstrip("0").rstrip(".") if math.isfinite(v) else "nan"


class SessionWriter:
    """Create or resume a session folder, one pose at a time, crash-safely.

    ``session.toml`` is written once; ``poses.csv`` is rewritten atomically with each
    new row, after that row's take is on disk, so a crash leaves either the old or
    the new file and never a row without its take. Resuming an existing folder
    continues the pose numbering (``config`` must then match the folder's, or be None).
    """

    def __init__(self, directory: str | os.PathLike[str], config: SessionConfig | None = None):
        self.directory = Path(directory)
        toml_path = self.directory / SESSION_FILE
        if toml_path.is_file():
            existing = load_session_config(toml_path)
            if config is not None and existing.model_dump() != config.model_dump():
                raise InputError(
                    "session.toml differs from the configuration given; resume with config=None "
                    "or start a new folder",
                    source=str(toml_path),
                )
            self.config = existing
        elif config is None:
            raise InputError(
                "no session.toml: a new session needs its configuration", source=str(self.directory)
            )
        else:
            self.config = config
            (self.directory / TAKES_DIR).mkdir(parents=True, exist_ok=True)
            write_text_atomic(toml_path, session_toml(config))
        (self.directory / TAKES_DIR).mkdir(parents=True, exist_ok=True)
        poses_path = self.directory / POSES_FILE
        if poses_path.is_file():
            self._text = poses_path.read_text(encoding="utf-8-sig")
            self._header, table = parse_poses(self._text, str(poses_path))
            self._last = int(table.pose.max()) if len(table) else 0
        else:
            self._header = list(POSE_COLUMNS)
            self._text = ",".join(POSE_COLUMNS) + "\n"
            self._last = 0
            write_text_atomic(poses_path, self._text)

    @property
    def next_pose(self) -> int:
        return self._last + 1

    def take_relpath(self, pose: int | None = None, format: str | None = None) -> str:
        """Suggested take path for ``pose`` (default the next), relative to the folder."""
        fmt = format or self.config.motion_capture.format or "motive-csv"
        return f"{TAKES_DIR}/pose_{pose or self.next_pose:04d}{EXTENSIONS[fmt]}"

    def append(
        self,
        *,
        take: str,
        t_s: float,
        commanded: ArrayLike,
        s_cmd: ArrayLike,
        dirs: ArrayLike,
        pose: int | None = None,
        extra: dict[str, str] | None = None,
    ) -> int:
        """Add one row to poses.csv (the take file must exist already); returns its pose number."""
        number = self.next_pose if pose is None else int(pose)
        if number <= self._last:
            raise ValueError(f"pose {number} is not after the last pose {self._last}")
        if not (self.directory / take).exists():
            raise InputError(
                f"take {take!r} does not exist; write it before its row",
                source=str(self.directory),
            )
        values = {"pose": str(number), "take": take, "t_s": _fmt(float(t_s))}
        for names, vec in (
            (("x_cmd", "y_cmd", "z_cmd"), commanded),
            (("s1_cmd", "s2_cmd", "s3_cmd"), s_cmd),
        ):
            values.update(
                {n: _fmt(float(v)) for n, v in zip(names, np.asarray(vec, dtype=float).reshape(3))}
            )
        values.update(
            {f"dir{k + 1}": str(int(d)) for k, d in enumerate(np.asarray(dirs).reshape(3))}
        )
        values.update(extra or {})
        new_columns = [k for k in values if k not in self._header]
        header, text = self._header, self._text
        if new_columns:
            if not parse_poses(text, POSES_FILE)[1].take:  # no rows yet: the header may grow
                header = header + new_columns
                text = ",".join(header) + "\n"
            else:
                raise ValueError(f"poses.csv has no column(s) {', '.join(new_columns)}")
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([values.get(h, "") for h in header])
        text = text if text.endswith("\n") or not text else text + "\n"
        text += buf.getvalue()
        parse_poses(
            text, str(self.directory / POSES_FILE)
        )  # never write a file we could not read back
        write_text_atomic(self.directory / POSES_FILE, text)
        self._text, self._last, self._header = text, number, header
        return number

    def add_take(
        self,
        take: Take,
        *,
        t_s: float,
        commanded: ArrayLike,
        s_cmd: ArrayLike,
        dirs: ArrayLike,
        format: str | None = None,
        extra: dict[str, str] | None = None,
        **writer_options: Any,
    ) -> int:
        """Write ``take`` under takes/ (atomically) and append its row (with ``extra`` columns,
        which a new folder's header gains); returns the pose number."""
        fmt = format or self.config.motion_capture.format or "motive-csv"
        rel = self.take_relpath(self.next_pose, fmt)
        write_take(self.directory / rel, take, fmt, **writer_options)
        return self.append(
            take=rel, t_s=t_s, commanded=commanded, s_cmd=s_cmd, dirs=dirs, extra=extra
        )
