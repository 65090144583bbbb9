"""``poses.csv`` of a calibration session, read and validated into a :class:`PoseTable`:
one row a pose, its take, the commanded point and sliders and the approach directions,
whatever measured the takes.

poses.csv may carry extra columns in any order; ``role`` (``fit`` | ``check``, empty = fit)
marks check poses, which identification predicts but does not fit.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cdprhost.errors import InputError

POSE_COLUMNS = (
    "pose",
    "take",
    "t_s",
    "x_cmd",
    "y_cmd",
    "z_cmd",
    "s1_cmd",
    "s2_cmd",
    "s3_cmd",
    "dir1",
    "dir2",
    "dir3",
)
ROLES = ("fit", "check")
_FLOAT_COLUMNS = ("t_s", "x_cmd", "y_cmd", "z_cmd", "s1_cmd", "s2_cmd", "s3_cmd")


@dataclass(frozen=True, eq=False)
class PoseTable:
    """poses.csv as arrays, one row per pose; ``lines`` are the rows' file line numbers;
    ``extra`` holds every other column, by header name, as text."""

    pose: np.ndarray  # (K,) int
    take: tuple[str, ...]
    t_s: np.ndarray  # (K,)
    commanded: np.ndarray  # (K, 3)
    s_cmd: np.ndarray  # (K, 3)
    dirs: np.ndarray  # (K, 3) int in {-1, 0, 1}
    lines: np.ndarray  # (K,) int
    roles: tuple[str, ...] = ()  # "fit" | "check" per row
    extra: dict[str, tuple[str, ...]] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.take)


def row_error(source: str, line: int, name: str, column: int, why: str) -> InputError:
    return InputError(f"line {line}, column '{name}' (column {column + 1}): {why}", source=source)


def parse_poses(text: str, source: str) -> tuple[list[str], PoseTable]:
    """Header and validated rows of a poses.csv text."""
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise InputError(f"empty file: expected the header {','.join(POSE_COLUMNS)}", source=source)
    header = [h.strip() for h in rows[0]]
    missing = [c for c in POSE_COLUMNS if c not in header]
    if missing:
        raise InputError(f"line 1: header lacks column(s) {', '.join(missing)}", source=source)
    col = {c: header.index(c) for c in header}
    others = [h for h in header if h and h not in POSE_COLUMNS and h != "role"]
    poses: list[int] = []
    takes: list[str] = []
    floats: list[list[float]] = []
    dirs: list[list[int]] = []
    lines: list[int] = []
    roles: list[str] = []
    extra: dict[str, list[str]] = {h: [] for h in others}
    for n, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue

        def cell(name: str, row: list[str] = row) -> str:
            return row[col[name]].strip() if col[name] < len(row) else ""

        def fail(name: str, why: str, n: int = n) -> InputError:
            return row_error(source, n, name, col[name], why)

        try:
            pose = int(cell("pose"))
        except ValueError:
            raise fail("pose", f"not an integer: {cell('pose')!r}") from None
        if pose < 1:
            raise fail("pose", f"must be >= 1, got {pose}")
        if pose in poses:
            raise fail("pose", f"pose {pose} already given on line {lines[poses.index(pose)]}")
        if not cell("take"):
            raise fail("take", "empty: expected the take's path relative to the session folder")
        vals = []
        for name in _FLOAT_COLUMNS:
            try:
                v = float(cell(name))
            except ValueError:
                raise fail(name, f"not a number: {cell(name)!r}") from None
            if not math.isfinite(v):
                raise fail(name, f"not a finite number: {cell(name)!r}")
            vals.append(v)
        d = []
        for name in ("dir1", "dir2", "dir3"):
            try:
                v = float(cell(name))
            except ValueError:
                v = math.nan
            if v not in (-1.0, 0.0, 1.0):
                raise fail(name, f"must be +1, -1 or 0, got {cell(name)!r}")
            d.append(int(v))
        role = (cell("role").lower() if "role" in col else "") or "fit"
        if role not in ROLES:
            raise fail("role", f"must be fit or check, got {role!r}")
        poses.append(pose)
        takes.append(cell("take"))
        floats.append(vals)
        dirs.append(d)
        lines.append(n)
        roles.append(role)
        for h in others:
            extra[h].append(cell(h))
    f = np.asarray(floats, dtype=float).reshape(-1, 7)
    table = PoseTable(
        np.asarray(poses, dtype=int),
        tuple(takes),
        f[:, 0],
        f[:, 1:4],
        f[:, 4:7],
        np.asarray(dirs, dtype=int).reshape(-1, 3),
        np.asarray(lines, dtype=int),
        tuple(roles),
        {h: tuple(v) for h, v in extra.items()},
    )
    return header, table


def read_poses(path: str | os.PathLike[str]) -> PoseTable:
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=str(path)) from None
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text", source=str(path)) from None
    return parse_poses(text, str(path))[1]
