"""The calibration session folder: ``session.toml``, ``poses.csv``, ``takes/``.

``load_session(dir)`` validates both files and returns a :class:`Session`, whose
``measure()`` turns every take into a base-frame effector point (arrays ready for
identification), listing rejected takes instead of using them.
:class:`SessionWriter` creates a folder, or resumes one, one pose at a time.

Beyond the spec, ``session.toml`` may hold ``[mocap.acceptance]`` (the take
checks' limits, :class:`~cdprhost.calibration.takes.AcceptanceLimits`); other
top-level tables and extra ``[session]`` keys are kept, and poses.csv may carry
extra columns in any order.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from cdprhost.calibration.readers import EXTENSIONS, Take, read_take, write_take
from cdprhost.calibration.takes import (
    AcceptanceLimits,
    MocapConfig,
    TakeMeasurement,
    TakeRejected,
    measure_effector,
)
from cdprhost.errors import InputError
from cdprhost.fileio.atomic import write_text_atomic

SESSION_FILE = "session.toml"
POSES_FILE = "poses.csv"
TAKES_DIR = "takes"
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
_FLOAT_COLUMNS = ("t_s", "x_cmd", "y_cmd", "z_cmd", "s1_cmd", "s2_cmd", "s3_cmd")


class SessionInfo(BaseModel):
    """``[session]``: the profile that commanded the poses; other keys are kept."""

    model_config = ConfigDict(extra="allow", frozen=True)
    profile: str = Field(min_length=1)


class SessionConfig(BaseModel):
    """The whole ``session.toml`` (extra top-level tables are allowed and kept)."""

    model_config = ConfigDict(extra="allow", frozen=True)
    session: SessionInfo
    mocap: MocapConfig


def validation_problems(exc: ValidationError) -> list[str]:
    out = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
        msg = {"missing": "missing required key", "extra_forbidden": "unknown key"}.get(
            err["type"], err["msg"].removeprefix("Value error, ")
        )
        out.append(f"{loc}: {msg}")
    return out


def load_session_config(path: str | os.PathLike[str]) -> SessionConfig:
    src = str(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=src) from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", source=src) from None
    try:
        return SessionConfig.model_validate(data)
    except ValidationError as exc:
        raise InputError(
            "invalid session configuration", source=src, problems=validation_problems(exc)
        ) from None


@dataclass(frozen=True, eq=False)
class PoseTable:
    """poses.csv as arrays, one row per pose; ``lines`` are the rows' file line numbers."""

    pose: np.ndarray  # (K,) int
    take: tuple[str, ...]
    t_s: np.ndarray  # (K,)
    commanded: np.ndarray  # (K, 3)
    s_cmd: np.ndarray  # (K, 3)
    dirs: np.ndarray  # (K, 3) int in {-1, 0, 1}
    lines: np.ndarray  # (K,) int

    def __len__(self) -> int:
        return len(self.take)


def parse_poses(text: str, source: str) -> tuple[list[str], PoseTable]:
    """Header and validated rows of a poses.csv text."""
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise InputError(f"empty file: expected the header {','.join(POSE_COLUMNS)}", source=source)
    header = [h.strip() for h in rows[0]]
    missing = [c for c in POSE_COLUMNS if c not in header]
    if missing:
        raise InputError(f"line 1: header lacks column(s) {', '.join(missing)}", source=source)
    col = {c: header.index(c) for c in POSE_COLUMNS}
    poses, takes, floats, dirs, lines = [], [], [], [], []
    for n, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue

        def cell(name: str, row: list[str] = row) -> str:
            return row[col[name]].strip() if col[name] < len(row) else ""

        def fail(name: str, why: str, n: int = n) -> InputError:
            return InputError(
                f"line {n}, column '{name}' (column {col[name] + 1}): {why}", source=source
            )

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
        poses.append(pose)
        takes.append(cell("take"))
        floats.append(vals)
        dirs.append(d)
        lines.append(n)
    f = np.asarray(floats, dtype=float).reshape(-1, 7)
    table = PoseTable(
        np.asarray(poses, dtype=int),
        tuple(takes),
        f[:, 0],
        f[:, 1:4],
        f[:, 4:7],
        np.asarray(dirs, dtype=int).reshape(-1, 3),
        np.asarray(lines, dtype=int),
    )
    return header, table


def read_poses(path: str | os.PathLike[str]) -> PoseTable:
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=str(path)) from None
    return parse_poses(text, str(path))[1]


@dataclass(frozen=True)
class RejectedTake:
    pose: int
    take: str
    reason: str  # a TakeRejected reason, or "unreadable"
    message: str


@dataclass(frozen=True, eq=False)
class SessionMeasurements:
    """Accepted poses only (K of them), in poses.csv order; rejected ones listed apart."""

    pose: np.ndarray  # (K,)
    measured: np.ndarray  # (K, 3) base frame, mm
    commanded: np.ndarray  # (K, 3)
    s_cmd: np.ndarray  # (K, 3)
    t_s: np.ndarray  # (K,)
    dirs: np.ndarray  # (K, 3)
    std: np.ndarray  # (K, 3) per-frame spread of each take
    base_fit_rms_mm: np.ndarray  # (K,)
    takes: tuple[TakeMeasurement, ...]
    rejected: tuple[RejectedTake, ...]

    def __len__(self) -> int:
        return int(self.measured.shape[0])

    def observations(self, sigma_mm: float = 0.05):
        """As :class:`cdprhost.calibration.fitting.Observations` (for identification)."""
        from cdprhost.calibration.fitting import Observations

        return Observations(self.measured, self.s_cmd, self.t_s, self.dirs.astype(float), sigma_mm)


@dataclass(frozen=True)
class Session:
    directory: Path
    config: SessionConfig
    poses: PoseTable

    def take_path(self, i: int) -> Path:
        """Path of the i-th row's take (0-based row index)."""
        return self.directory / self.poses.take[i]

    def measure_take(self, i: int, limits: AcceptanceLimits | None = None) -> TakeMeasurement:
        take = read_take(self.take_path(i), self.config.mocap.format)
        return measure_effector(take, self.config.mocap, limits)

    def measure(
        self, limits: AcceptanceLimits | None = None, *, strict: bool = False
    ) -> SessionMeasurements:
        """Measure every take. ``strict``: raise on the first rejected or unreadable take."""
        keep: list[int] = []
        results: list[TakeMeasurement] = []
        rejected: list[RejectedTake] = []
        p = self.poses
        for i in range(len(p)):
            try:
                results.append(self.measure_take(i, limits))
                keep.append(i)
            except InputError as exc:
                if strict:
                    raise InputError(
                        f"pose {p.pose[i]} (poses.csv line {p.lines[i]}): {exc}"
                    ) from None
                reason = exc.reason if isinstance(exc, TakeRejected) else "unreadable"
                rejected.append(RejectedTake(int(p.pose[i]), p.take[i], reason, str(exc)))
        k = np.asarray(keep, dtype=int)
        return SessionMeasurements(
            p.pose[k],
            np.array([r.point for r in results]).reshape(-1, 3),
            p.commanded[k],
            p.s_cmd[k],
            p.t_s[k],
            p.dirs[k],
            np.array([r.std for r in results]).reshape(-1, 3),
            np.array([r.base_fit_rms_mm for r in results]),
            tuple(results),
            tuple(rejected),
        )


def load_session(directory: str | os.PathLike[str]) -> Session:
    """Read and validate a session folder (takes are read later, by ``measure``)."""
    root = Path(directory)
    if not root.is_dir():
        raise InputError("not a session folder (no such directory)", source=str(root))
    for name in (SESSION_FILE, POSES_FILE):
        if not (root / name).is_file():
            raise InputError(f"missing {name}", source=str(root))
    return Session(root, load_session_config(root / SESSION_FILE), read_poses(root / POSES_FILE))


def _toml_value(v) -> str:
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

    mocap = config.mocap
    out = ["[session]"] + [
        f"{k} = {_toml_value(v)}" for k, v in config.session.model_dump().items()
    ]
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
    extra = {k: v for k, v in config.model_dump().items() if k not in ("session", "mocap")}
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
        fmt = format or self.config.mocap.format or "motive-csv"
        return f"{TAKES_DIR}/pose_{pose or self.next_pose:04d}{EXTENSIONS[fmt]}"

    def append(
        self,
        *,
        take: str,
        t_s: float,
        commanded,
        s_cmd,
        dirs,
        pose: int | None = None,
        extra: dict[str, str] | None = None,
    ) -> int:
        """Add one row to poses.csv (the take file must exist already); returns its pose number."""
        number = self.next_pose if pose is None else int(pose)
        if number <= self._last:
            raise ValueError(f"pose {number} is not after the last pose {self._last}")
        if not (self.directory / take).is_file():
            raise InputError(
                f"take file {take!r} does not exist; write it before its row",
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
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([values.get(h, "") for h in self._header])
        text = self._text if self._text.endswith("\n") or not self._text else self._text + "\n"
        text += buf.getvalue()
        parse_poses(
            text, str(self.directory / POSES_FILE)
        )  # never write a file we could not read back
        write_text_atomic(self.directory / POSES_FILE, text)
        self._text, self._last = text, number
        return number

    def add_take(
        self,
        take: Take,
        *,
        t_s: float,
        commanded,
        s_cmd,
        dirs,
        format: str | None = None,
        **writer_options,
    ) -> int:
        """Write ``take`` under takes/ (atomically) and append its row; returns the pose number."""
        fmt = format or self.config.mocap.format or "motive-csv"
        rel = self.take_relpath(self.next_pose, fmt)
        write_take(self.directory / rel, take, fmt, **writer_options)
        return self.append(take=rel, t_s=t_s, commanded=commanded, s_cmd=s_cmd, dirs=dirs)
