"""Guided calibration: a resumable state machine and the loop that drives it.

:class:`WizardState` is pure: it says what to do next (:class:`MoveTo` a pose,
:class:`RecordTake` there, :class:`Identify`, :class:`Finished`) and returns a new
state for each outcome. :class:`CalibrationWizard` runs it against two small
interfaces, a :class:`WizardDevice` (moves and settles the machine) and a
:class:`TakeSource` (produces a take file for a pose: the user, a watched folder,
a folder of recorded takes), validating each take at once and appending it to the
session folder before going on. Everything recorded is on disk as soon as it is
accepted, so a crash or Ctrl-C loses nothing; running again on the same folder
resumes from ``plan.csv`` and the rows already in ``poses.csv``.
"""

from __future__ import annotations

import csv
import dataclasses
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from cdprhost.calibration.identification import Identification, calibrated_profile, identify_session
from cdprhost.calibration.planning import PosePlan, plan_csv, plan_poses, read_plan_csv
from cdprhost.calibration.readers import read_take
from cdprhost.calibration.session import POSE_COLUMNS, POSES_FILE, SessionConfig, SessionWriter
from cdprhost.calibration.takes import MocapConfig, TakeMeasurement, TakeRejected, measure_effector
from cdprhost.errors import InputError
from cdprhost.fileio.atomic import atomic_open, write_text_atomic
from cdprhost.jsonsafe import dumps
from cdprhost.kinematics import MachineModel
from cdprhost.profile import MachineProfile, save_profile

PLAN_FILE = "plan.csv"
REPORT_FILE = "identification.json"
PROFILE_FILE = "calibrated.toml"
EXTRA_COLUMNS = ("role", "plan_pose", "mocap_file")


# ------------------------------------------------------------------ actions
@dataclass(frozen=True)
class MoveTo:
    index: int  # 0-based row of the plan
    waypoints: np.ndarray  # (2, 3): the approach point, then the pose


@dataclass(frozen=True)
class RecordTake:
    index: int
    attempt: int  # 1-based
    last_problem: str | None = None


@dataclass(frozen=True)
class Identify:
    pass


@dataclass(frozen=True)
class Finished:
    reason: str


# ------------------------------------------------------------------ state
@dataclass(frozen=True)
class WizardState:
    """Where a calibration session stands. Every transition returns a new state."""

    plan: PosePlan
    recorded: frozenset[int] = frozenset()
    skipped: frozenset[int] = frozenset()
    at: int | None = None  # plan row the machine is settled at
    attempts: int = 0
    last_problem: str | None = None
    identified: bool = False
    max_attempts: int = 3
    min_fit_poses: int = 4

    @property
    def pending(self) -> list[int]:
        return [
            i
            for i in range(len(self.plan.poses))
            if i not in self.recorded and i not in self.skipped
        ]

    @property
    def fit_recorded(self) -> int:
        return sum(self.plan.roles[i] == "fit" for i in self.recorded)

    def next_action(self) -> MoveTo | RecordTake | Identify | Finished:
        pending = self.pending
        if pending:
            i = pending[0]
            if self.at != i:
                return MoveTo(i, np.vstack([self.plan.approach[i], self.plan.poses[i]]))
            return RecordTake(i, self.attempts + 1, self.last_problem)
        if self.identified:
            return Finished("identified")
        if self.fit_recorded < self.min_fit_poses:
            return Finished(
                f"only {self.fit_recorded} fit pose(s) recorded; {self.min_fit_poses} are needed"
            )
        return Identify()

    def moved(self, index: int) -> WizardState:
        return dataclasses.replace(self, at=index, attempts=0, last_problem=None)

    def accepted(self, index: int) -> WizardState:
        return dataclasses.replace(
            self, recorded=self.recorded | {index}, attempts=0, last_problem=None
        )

    def rejected(self, index: int, problem: str) -> WizardState:
        """Ask again at the same pose, until ``max_attempts``; then skip it."""
        attempts = self.attempts + 1
        if attempts >= self.max_attempts:
            return dataclasses.replace(
                self, skipped=self.skipped | {index}, attempts=0, last_problem=problem
            )
        return dataclasses.replace(self, attempts=attempts, last_problem=problem)

    def skip(self, index: int) -> WizardState:
        return dataclasses.replace(
            self, skipped=self.skipped | {index}, attempts=0, last_problem=None
        )

    def done(self) -> WizardState:
        return dataclasses.replace(self, identified=True)


# ------------------------------------------------------------------ interfaces
class WizardDevice(Protocol):
    """Implemented by :class:`cdprhost.machine.Machine`."""

    def visit(self, points: np.ndarray) -> tuple[np.ndarray, float]:
        """Move the effector through ``points`` (machine frame, in order), stop at the last,
        wait until it has settled; return the absolute module steps (3,) and device time (s)."""


class TakeSource(Protocol):
    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        """A take file recorded with the effector settled at ``pose`` (plan row ``index``)."""


@dataclass(frozen=True)
class WizardOptions:
    n_poses: int = 4
    n_check: int = 3
    criterion: str = "D"
    seed: int = 0
    noise_floor_mm: float = 0.05
    max_offset_mm: float = (
        30.0  # a take further than this from the commanded pose is the wrong take
    )
    max_attempts: int = 3


@dataclass(frozen=True)
class WizardOutcome:
    state: WizardState
    identification: Identification | None
    profile: MachineProfile | None
    profile_path: Path | None
    session: Path


# ------------------------------------------------------------------ session folder
def recorded_rows(directory: Path) -> list[dict[str, str]]:
    path = directory / POSES_FILE
    if not path.is_file():
        return []
    with open(path, encoding="utf-8-sig", newline="") as fh:
        return [row for row in csv.DictReader(fh) if any((v or "").strip() for v in row.values())]


def resume_state(plan: PosePlan, rows: list[dict[str, str]], max_attempts: int = 3) -> WizardState:
    """The state after the rows already in poses.csv (matched to the plan by ``plan_pose``)."""
    done = {int(r["plan_pose"]) - 1 for r in rows if (r.get("plan_pose") or "").strip()}
    return WizardState(
        plan, frozenset(i for i in done if 0 <= i < len(plan.poses)), max_attempts=max_attempts
    )


def validate_take(
    path: Path, mocap: MocapConfig, pose: np.ndarray, max_offset_mm: float
) -> TakeMeasurement:
    """Read and measure a take now (markers, static effector, base fit), and check it was
    taken at this pose; raises :class:`TakeRejected` naming the problem."""
    measurement = measure_effector(read_take(path, mocap.format), mocap)
    offset = float(np.linalg.norm(measurement.point - pose))
    if offset > max_offset_mm:
        raise TakeRejected(
            f"the effector measures {offset:.1f} mm from the commanded pose ({', '.join(f'{v:.1f}' for v in pose)}); "
            f"limit {max_offset_mm:g} mm: is this the take of another pose?",
            source=str(path),
            reason="wrong-pose",
        )
    return measurement


class CalibrationWizard:
    """Plan (or resume), visit every pose, record and validate takes, identify."""

    def __init__(
        self,
        session_dir: str | Path,
        profile: MachineProfile,
        device: WizardDevice,
        takes: TakeSource,
        *,
        mocap: MocapConfig | None = None,
        options: WizardOptions = WizardOptions(),
        log: Callable[[str], None] = print,
        profile_ref: str | None = None,
    ):
        self.dir = Path(session_dir)
        self.profile = profile
        self.model = MachineModel.from_profile(profile)
        self.device = device
        self.takes = takes
        self.options = options
        self.log = log
        self.dir.mkdir(parents=True, exist_ok=True)
        plan_path = self.dir / PLAN_FILE
        if plan_path.is_file():
            self.plan = read_plan_csv(plan_path, self.model)
            self.log(
                f"resuming session {self.dir}: plan of {len(self.plan.poses)} poses from {PLAN_FILE}"
            )
        else:
            self.plan = plan_poses(
                self.model,
                options.n_poses,
                n_check=options.n_check,
                criterion=options.criterion,
                seed=options.seed,
            )
            write_text_atomic(plan_path, plan_csv(self.plan))
        if not (self.dir / POSES_FILE).is_file():
            write_text_atomic(self.dir / POSES_FILE, ",".join(POSE_COLUMNS + EXTRA_COLUMNS) + "\n")
        config = None
        if not (self.dir / "session.toml").is_file():
            if mocap is None:
                raise InputError(
                    "a new session needs the motion-capture configuration (markers)",
                    source=str(self.dir),
                )
            config = SessionConfig(session={"profile": profile_ref or profile.name}, mocap=mocap)
        self.writer = SessionWriter(self.dir, config)
        rows = recorded_rows(self.dir)
        self.state = resume_state(self.plan, rows, options.max_attempts)
        self._t_offset = max((float(r["t_s"]) for r in rows), default=0.0)
        self._t0: float | None = None  # device time of the first settle of this run
        self._steps: np.ndarray | None = None
        self.identification: Identification | None = None
        self.calibrated: MachineProfile | None = None

    # --------------------------------------------------------------- steps
    def step(self) -> MoveTo | RecordTake | Identify | Finished:
        """Carry out the next action; returns the action it carried out."""
        action = self.state.next_action()
        if isinstance(action, MoveTo):
            self._move(action)
        elif isinstance(action, RecordTake):
            self._record(action)
        elif isinstance(action, Identify):
            self._identify()
        return action

    def run(self) -> WizardOutcome:
        while not isinstance(self.step(), Finished):
            pass
        return self.outcome

    def _label(self, i: int) -> str:
        p = self.plan.poses[i]
        return f"pose {i + 1}/{len(self.plan.poses)} ({self.plan.roles[i]}) at ({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f})"

    def _move(self, action: MoveTo) -> None:
        self.log(f"moving to {self._label(action.index)}")
        steps, t = self.device.visit(action.waypoints)
        self._steps = np.asarray(steps, dtype=np.int64)[:3]
        if self._t0 is None:
            self._t0 = float(t)
        self._t = self._t_offset + float(t) - self._t0
        self.state = self.state.moved(action.index)

    def _record(self, action: RecordTake) -> None:
        i = action.index
        if action.last_problem:
            self.log(
                f"take rejected: {action.last_problem}; attempt {action.attempt} of {self.options.max_attempts}"
            )
        else:
            self.log(f"{self._label(i)} has settled: record a take")
        path = Path(self.takes.take_for(i, self.plan.poses[i], action.attempt))
        try:
            m = validate_take(
                path, self.writer.config.mocap, self.plan.poses[i], self.options.max_offset_mm
            )
        except InputError as exc:  # TakeRejected or an unreadable file
            self.state = self.state.rejected(i, str(exc))
            if i in self.state.skipped:
                self.log(
                    f"{self._label(i)} skipped after {self.options.max_attempts} rejected takes: {exc}"
                )
            return
        rel = f"takes/pose_{self.writer.next_pose:04d}{path.suffix}"  # the take exactly as recorded
        with atomic_open(self.dir / rel, "wb") as out, open(path, "rb") as src:
            shutil.copyfileobj(src, out)
        s_cmd = self.model.sliders_from_steps(self._steps)
        self.writer.append(
            take=rel,
            t_s=self._t,
            commanded=self.plan.poses[i],
            s_cmd=s_cmd,
            dirs=self.plan.directions[i],
            extra={"role": self.plan.roles[i], "plan_pose": str(i + 1), "mocap_file": str(path)},
        )
        self.state = self.state.accepted(i)
        self.log(
            f"recorded {self._label(i)}: base fit {m.base_fit_rms_mm:.3f} mm, spread {m.spread_mm:.3f} mm, "
            f"{m.n_frames_used} frames"
        )

    def _identify(self) -> None:
        self.log("identifying the 12 parameters")
        result = identify_session(self.dir, self.model, noise_floor_mm=self.options.noise_floor_mm)
        write_text_atomic(self.dir / REPORT_FILE, dumps(result.to_json(), indent=2) + "\n")
        self.identification = result
        if result.ok:
            self.calibrated = calibrated_profile(
                self.profile, result, session=str(self.dir.resolve())
            )
            save_profile(self.calibrated, self.dir / PROFILE_FILE)
        self.state = self.state.done()

    @property
    def outcome(self) -> WizardOutcome:
        prof = self.calibrated
        return WizardOutcome(
            self.state,
            self.identification,
            prof,
            self.dir / PROFILE_FILE if prof else None,
            self.dir,
        )


# ------------------------------------------------------------------ take sources
@dataclass
class FolderWatcher:
    """Waits for a new take file in ``folder`` (one not seen before), complete and stable."""

    folder: Path
    timeout_s: float = 600.0
    poll_s: float = 0.2
    clock: Callable[[], float] = field(default=None)  # type: ignore[assignment]
    sleep: Callable[[float], None] = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        import time

        self.folder = Path(self.folder)
        self.clock = self.clock or time.monotonic
        self.sleep = self.sleep or time.sleep
        self.seen = set(self._files())

    def _files(self) -> dict[Path, int]:
        if not self.folder.is_dir():
            return {}
        return {
            p: p.stat().st_size
            for p in self.folder.iterdir()
            if p.is_file() and not p.name.startswith(".") and not p.name.endswith(".tmp")
        }

    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        deadline = self.clock() + self.timeout_s
        sizes: dict[Path, int] = {}
        while True:
            files = self._files()
            new = {p: s for p, s in files.items() if p not in self.seen}
            stable = sorted(
                (p for p, s in new.items() if sizes.get(p) == s and s > 0),
                key=lambda p: p.stat().st_mtime,
            )
            if stable:
                self.seen.update(new)
                return stable[-1]
            sizes = new
            if self.clock() > deadline:
                raise InputError(
                    f"no new take file appeared within {self.timeout_s:g} s",
                    source=str(self.folder),
                )
            self.sleep(self.poll_s)


@dataclass
class NumberedTakes:
    """Takes recorded beforehand: the file whose name ends in the plan pose number (``pose_3.csv``)."""

    folder: Path

    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        import re

        folder = Path(self.folder)
        for p in sorted(folder.iterdir()) if folder.is_dir() else []:
            numbers = re.findall(r"\d+", p.stem)
            if p.is_file() and numbers and int(numbers[-1]) == index + 1:
                return p
        raise InputError(
            f"no take for plan pose {index + 1} (expected a file name ending in {index + 1})",
            source=str(folder),
        )


# ------------------------------------------------------------------ the machine over the link
