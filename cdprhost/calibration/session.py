"""The calibration session folder, read in one place: ``session.toml``, ``poses.csv``, ``takes/``.

``load_session(dir)`` validates both files into one typed :class:`Session` (settings with
the acceptance thresholds, poses with their roles, take paths resolved inside the folder),
which planning, identification, diagnosis and the wizard all consume. ``measure()`` turns
every take into a base-frame effector point with its standard error, listing refused takes
instead of using them, and the resulting :class:`SessionMeasurements` builds the
observations (with each pose's noise, :mod:`.pose_noise`) for identification and diagnosis.
:mod:`.session_writer` writes folders.

Beyond the spec, ``session.toml`` may hold ``[mocap.acceptance]`` (the take checks'
thresholds, :class:`~cdprhost.calibration.acceptance.AcceptanceLimits`) and ``noise_mm``
(under ``[mocap]`` or ``[session]``); other top-level tables and extra ``[session]`` keys
are kept. poses.csv may carry extra columns in any order; ``role`` (``fit`` | ``check``,
empty = fit) marks check poses, which identification predicts but does not fit.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from cdprhost.calibration.acceptance import AcceptanceLimits
from cdprhost.calibration.camera.config import CameraConfig
from cdprhost.calibration.config_input import contained_path, read_toml, validation_problems
from cdprhost.calibration.fitting import Observations
from cdprhost.calibration.pose_noise import PoseNoise, camera_noise, pose_noise
from cdprhost.calibration.readers import read_take
from cdprhost.calibration.takes import (
    MocapConfig,
    TakeMeasurement,
    TakeRejected,
    TakeSeries,
    judge_takes,
    prepare_take,
)
from cdprhost.errors import InputError

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
ROLES = ("fit", "check")
_FLOAT_COLUMNS = ("t_s", "x_cmd", "y_cmd", "z_cmd", "s1_cmd", "s2_cmd", "s3_cmd")


class SessionInfo(BaseModel):
    """``[session]``: the profile that commanded the poses; other keys are kept."""

    model_config = ConfigDict(extra="allow", frozen=True)
    profile: str = Field(min_length=1)
    noise_mm: float | None = Field(
        default=None,
        gt=0,
        allow_inf_nan=False,
        description="declared mocap noise (mm per coordinate)",
    )


class SessionConfig(BaseModel):
    """The whole ``session.toml`` (extra top-level tables are allowed and kept): a
    motion-capture session (``[mocap]``) or a camera session (``[camera]``,
    camera-session.md), exactly one of them."""

    model_config = ConfigDict(extra="allow", frozen=True)
    session: SessionInfo
    mocap: MocapConfig | None = None
    camera: CameraConfig | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> SessionConfig:
        if (self.mocap is None) == (self.camera is None):
            raise ValueError(
                "a session has exactly one of [mocap] (motion capture) and [camera] "
                f"(one camera and ChArUco boards); this one has {'both' if self.mocap else 'neither'}"
            )
        return self

    @property
    def motion_capture(self) -> MocapConfig:
        """``[mocap]``; a camera session has none (InputError)."""
        if self.mocap is None:
            raise InputError(
                "this is a camera session ([camera]): it has no motion-capture takes",
                source=SESSION_FILE,
            )
        return self.mocap

    @property
    def declared_noise_mm(self) -> float | None:
        """``accuracy_mm`` of ``[mocap]`` (or of ``[camera.acceptance]``), else its
        ``noise_mm``, else ``noise_mm`` of ``[session]``."""
        if self.mocap is not None:
            values = (self.mocap.accuracy_mm, self.mocap.noise_mm, self.session.noise_mm)
        else:
            accuracy = self.camera.acceptance.accuracy_mm if self.camera else None
            values = (accuracy, None, self.session.noise_mm)
        for value in values:
            if value is not None:
                return value
        return None

    @property
    def acceptance(self) -> AcceptanceLimits:
        return self.mocap.acceptance if self.mocap is not None else self.camera.acceptance  # type: ignore[union-attr]


def load_session_config(path: str | os.PathLike[str]) -> SessionConfig:
    src = str(path)
    data = read_toml(path)
    try:
        return SessionConfig.model_validate(data)
    except ValidationError as exc:
        raise InputError(
            "invalid session configuration", source=src, problems=validation_problems(exc)
        ) from None


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


def _row_error(source: str, line: int, name: str, column: int, why: str) -> InputError:
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
            return _row_error(source, n, name, col[name], why)

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


@dataclass(frozen=True, eq=False)
class RejectedTake:
    pose: int
    take: str
    reason: str  # one of acceptance.REASONS
    message: str

    def __str__(self) -> str:
        return f"pose {self.pose} ({self.take}): {self.reason}: {self.message}"


@dataclass(frozen=True, eq=False)
class SessionMeasurements:
    """Accepted poses only (K of them), in poses.csv order; refused ones listed apart."""

    pose: np.ndarray  # (K,)
    roles: tuple[str, ...]
    measured: np.ndarray  # (K, 3) base frame, mm
    commanded: np.ndarray  # (K, 3)
    s_cmd: np.ndarray  # (K, 3)
    t_s: np.ndarray  # (K,)
    dirs: np.ndarray  # (K, 3)
    se: np.ndarray  # (K, 3) standard error of each take's centre
    base_fit_rms_mm: np.ndarray  # (K,)
    takes: tuple[TakeMeasurement, ...]
    rejected: tuple[RejectedTake, ...]
    declared_noise_mm: float | None = None
    # a camera session's noise (camera-session.md, :mod:`.camera.session`): each pose's full
    # covariance (K, 3, 3), the common vector's (3, 3), the parameters' part (12, 12); what
    # refuses the session whatever the fit (calibration views of poor coverage); notes
    covariance: np.ndarray | None = None
    common_covariance: np.ndarray | None = None
    parameter_covariance: np.ndarray | None = None
    frame_covariance: np.ndarray | None = None
    refusals: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.measured.shape[0])

    @property
    def take_sigma_mm(self) -> np.ndarray:
        """Each pose's noise from its take alone, (K,) mm per coordinate."""
        return np.sqrt(np.mean(self.se**2, axis=1)) if len(self) else np.zeros(0)

    def noise(
        self, steps_per_mm: np.ndarray | float = 400.0, *, floor_mm: float | None = None
    ) -> PoseNoise:
        """The one noise model (:func:`~.pose_noise.pose_noise`); ``floor_mm`` overrides the
        declared noise."""
        if self.covariance is not None:
            return camera_noise(
                self.covariance,
                self.take_sigma_mm,
                self.declared_noise_mm if floor_mm is None else floor_mm,
                self.common_covariance,
                self.parameter_covariance,
                self.frame_covariance,
            )
        return pose_noise(
            self.take_sigma_mm,
            declared_mm=self.declared_noise_mm if floor_mm is None else floor_mm,
            sliders=self.s_cmd,
            measured=self.measured,
            steps_per_mm=steps_per_mm,
        )

    def observations(self, noise: PoseNoise | None = None) -> Observations:
        """The observations of identification and diagnosis (the one builder)."""
        n = noise or self.noise()
        return Observations(
            self.measured, self.s_cmd, self.t_s, self.dirs.astype(float), n.sigma_mm, n.covariance
        )


@dataclass(frozen=True)
class Session:
    directory: Path
    config: SessionConfig
    poses: PoseTable
    take_paths: tuple[Path, ...] = ()

    @property
    def warnings(self) -> list[str]:
        unknown = self.config.acceptance.unknown_keys
        return (
            [
                f"{SESSION_FILE}: [{'mocap' if self.config.mocap else 'camera'}.acceptance] key(s) not known here, ignored: {', '.join(unknown)}"
            ]
            if unknown
            else []
        )

    @property
    def check_poses(self) -> np.ndarray:
        """Pose numbers marked ``check``."""
        return np.asarray(self.poses.pose[np.array(self.poses.roles) == "check"])

    def take_path(self, i: int) -> Path:
        """Path of the i-th row's take (0-based row index), inside the session folder."""
        return self.take_paths[i] if self.take_paths else self.directory / self.poses.take[i]

    def prepare(self, i: int, limits: AcceptanceLimits | None = None) -> TakeSeries:
        mocap = self.config.motion_capture
        return prepare_take(read_take(self.take_path(i), mocap.format), mocap, limits)

    def measure(
        self, limits: AcceptanceLimits | None = None, *, strict: bool = False
    ) -> SessionMeasurements:
        """Measure every take (their noise correlation pooled, :func:`~.takes.judge_takes`).
        ``strict``: raise on the first refused or unreadable take."""
        lim = limits or self.config.acceptance
        p = self.poses
        outcome: dict[int, TakeMeasurement | InputError] = {}
        series: list[TakeSeries] = []
        rows: list[int] = []
        for i in range(len(p)):
            try:
                series.append(self.prepare(i, lim))
                rows.append(i)
            except InputError as exc:
                outcome[i] = exc
        outcome.update(zip(rows, judge_takes(series, lim)))
        keep: list[int] = []
        results: list[TakeMeasurement] = []
        rejected: list[RejectedTake] = []
        for i in range(len(p)):
            r = outcome[i]
            if isinstance(r, TakeMeasurement):
                keep.append(i)
                results.append(r)
                continue
            if strict:
                raise InputError(f"pose {p.pose[i]} (poses.csv line {p.lines[i]}): {r}") from None
            reason = r.reason if isinstance(r, TakeRejected) else "unreadable"
            rejected.append(RejectedTake(int(p.pose[i]), p.take[i], reason, str(r)))
        k = np.asarray(keep, dtype=int)
        return SessionMeasurements(
            p.pose[k],
            tuple(p.roles[i] for i in keep) if p.roles else ("fit",) * len(keep),
            np.array([r.point for r in results]).reshape(-1, 3),
            p.commanded[k],
            p.s_cmd[k],
            p.t_s[k],
            p.dirs[k],
            np.array([r.se for r in results]).reshape(-1, 3),
            np.array([r.base_fit_rms_mm for r in results]),
            tuple(results),
            tuple(rejected),
            self.config.declared_noise_mm,
        )


def load_session(directory: str | os.PathLike[str]) -> Session:
    """Read and validate a session folder (takes are read later, by ``measure``).

    Every take path must stay inside the folder: an absolute path or a ``..`` escape is
    refused, naming its poses.csv line."""
    root = Path(directory)
    if not root.is_dir():
        raise InputError("not a session folder (no such directory)", source=str(root))
    for name in (SESSION_FILE, POSES_FILE):
        if not (root / name).is_file():
            raise InputError(f"missing {name}", source=str(root))
    config = load_session_config(root / SESSION_FILE)
    poses_path = root / POSES_FILE
    text = _read_text(poses_path)
    header, poses = parse_poses(text, str(poses_path))
    paths: list[Path] = []
    for take, line in zip(poses.take, poses.lines):
        where = contained_path(root, take)
        if isinstance(where, str):
            raise _row_error(str(poses_path), int(line), "take", header.index("take"), where)
        paths.append(where)
    return Session(root, config, poses, tuple(paths))


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=str(path)) from None
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text", source=str(path)) from None
