"""The calibration session folder, read in one place: ``session.toml``, ``poses.csv``, ``takes/``.

``load_session(dir)`` validates both files into one typed :class:`Session` (settings with
the acceptance thresholds, poses with their roles, take paths resolved inside the folder),
which planning, identification, diagnosis and the wizard all consume. The session stands
above the measurement sources: ``measure()`` turns every motion-capture take
(:mod:`.mocap`) into a base-frame effector point with its standard error, listing refused
takes instead of using them (a camera session is measured by :mod:`.camera.session`), and
the resulting :class:`~.measurements.SessionMeasurements` builds the observations (with
each pose's noise, :mod:`.pose_noise`) for identification and diagnosis. poses.csv is read
by :mod:`.poses`; :mod:`.session_writer` writes folders.

Beyond the spec, ``session.toml`` may hold ``[mocap.acceptance]`` (the take checks'
thresholds, :class:`~cdprhost.calibration.acceptance.AcceptanceLimits`) and ``noise_mm``
(under ``[mocap]`` or ``[session]``); other top-level tables and extra ``[session]`` keys
are kept.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from cdprhost.calibration.acceptance import AcceptanceLimits
from cdprhost.calibration.camera.config import CameraConfig
from cdprhost.calibration.config_input import contained_path, read_toml, validation_problems
from cdprhost.calibration.measurements import RejectedTake, SessionMeasurements
from cdprhost.calibration.mocap.readers import read_take
from cdprhost.calibration.mocap.takes import MocapConfig, prepare_take
from cdprhost.calibration.poses import PoseTable, parse_poses, row_error
from cdprhost.calibration.takes import TakeMeasurement, TakeRejected, TakeSeries, judge_takes
from cdprhost.errors import InputError

SESSION_FILE = "session.toml"
POSES_FILE = "poses.csv"
TAKES_DIR = "takes"


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
            raise row_error(str(poses_path), int(line), "take", header.index("take"), where)
        paths.append(where)
    return Session(root, config, poses, tuple(paths))


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", source=str(path)) from None
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text", source=str(path)) from None


def mocap_for_session(
    session: str | os.PathLike[str],
    config_path: str | os.PathLike[str] | None = None,
    virtual: MocapConfig | None = None,
) -> MocapConfig | None:
    """The ``[mocap]`` configuration a wizard needs for ``session``: None when the folder
    already has its ``session.toml`` (resuming), else the one in ``config_path`` (a TOML
    file with the ``[mocap]`` table), else ``virtual`` (the simulator's); :class:`InputError`
    when a new session has none (checked before anything is written)."""
    if (Path(session) / SESSION_FILE).is_file():
        return None
    if config_path:
        return load_session_config(config_path).motion_capture
    if virtual is not None:
        return virtual
    raise InputError(
        "a new session needs the motion-capture configuration: a TOML file with the [mocap] "
        "table of session.toml (base markers, effector markers and offset)",
        source=str(session),
    )
