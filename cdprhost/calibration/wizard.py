"""Guided calibration: the loop that drives the wizard's state machine (:mod:`.wizard_state`).

:class:`CalibrationWizard` runs the state against two small interfaces, a
:class:`WizardDevice` (moves and settles the machine: :class:`cdprhost.machine.Machine`)
and a :class:`TakeSource` (produces a take file for a pose: the user, a watched folder,
takes recorded beforehand, :mod:`.take_sources`). Each take is judged at once (its noise
pooled with the session's earlier takes); a refused take sends the machine to the pose
again and a new take is asked for. Sound takes are appended to the session folder before
going on, so a crash or Ctrl-C loses nothing; running again on the same folder resumes
from ``plan.csv`` and the rows already in ``poses.csv``.

The identification verifies the fit poses on the check poses, then refines on all of
them (:func:`~.identification.identify_verified`). When the trust gate refuses, or the
check poses disagree, the wizard plans extra poses by D-optimal
augmentation of the poses measured (:mod:`.augmentation`), appends them to the plan and
asks for them, then identifies again (at most ``max_augment_rounds`` times).
"""

from __future__ import annotations

import dataclasses
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from cdprhost.calibration.augmentation import extend_plan, extra_poses
from cdprhost.calibration.camera.config import CameraConfig, intrinsics_toml
from cdprhost.calibration.camera.intrinsics import Intrinsics
from cdprhost.calibration.camera.takes import judge_camera_take, session_intrinsics
from cdprhost.calibration.identification import Identification, calibrated_profile
from cdprhost.calibration.mocap.readers import read_take
from cdprhost.calibration.mocap.takes import MocapConfig, prepare_take
from cdprhost.calibration.plan_files import plan_csv, read_plan_csv
from cdprhost.calibration.planning import plan_poses
from cdprhost.calibration.poses import POSE_COLUMNS, read_poses
from cdprhost.calibration.session import POSES_FILE, SessionConfig
from cdprhost.calibration.session_identification import identify_session
from cdprhost.calibration.session_writer import SessionWriter
from cdprhost.calibration.take_sources import FolderWatcher, NumberedTakes
from cdprhost.calibration.take_statistics import TakeStatistics
from cdprhost.calibration.takes import TakeMeasurement, TakeRejected, judge_in_session
from cdprhost.calibration.trust import TrustLimits
from cdprhost.calibration.verification import DEFAULT_ALPHA
from cdprhost.calibration.wizard_state import (
    Action,
    Finished,
    IdentifyStep,
    MoveTo,
    PlanMore,
    RecordTake,
    WizardState,
    resume_state,
)
from cdprhost.errors import CdprError, InputError
from cdprhost.fileio.atomic import atomic_open, write_text_atomic
from cdprhost.jsonsafe import dumps
from cdprhost.kinematics import MachineModel
from cdprhost.profile import MachineProfile, save_profile

__all__ = [
    "CalibrationWizard",
    "Finished",
    "FolderWatcher",
    "IdentifyStep",
    "MoveTo",
    "NumberedTakes",
    "PlanMore",
    "RecordTake",
    "WizardOptions",
    "WizardOutcome",
    "WizardState",
    "resume_state",
    "validate_take",
]

PLAN_FILE = "plan.csv"
REPORT_FILE = "identification.json"
PROFILE_FILE = "calibrated.toml"
EXTRA_COLUMNS = ("role", "plan_pose", "mocap_file")


class WizardDevice(Protocol):
    """Implemented by :class:`cdprhost.machine.Machine`."""

    def visit(self, points: np.ndarray) -> tuple[np.ndarray, float]:
        """Move the effector through ``points`` (machine frame, in order), stop at the last,
        wait until it has settled; return the absolute module steps (3,) and device time (s)."""
        ...


class TakeSource(Protocol):
    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        """A take file recorded with the effector settled at ``pose`` (plan row ``index``)."""
        ...


@dataclass(frozen=True)
class WizardOptions:
    n_poses: int = 4  # the paper's four optimal poses, planned over the whole workspace
    n_check: int = 3  # verify the four, then refine on all seven
    refine: bool = True
    alpha: float = DEFAULT_ALPHA  # false-alarm rate of the check-pose verification
    criterion: str = "D"
    seed: int = 0
    noise_floor_mm: float | None = None  # added to each take's standard error (None: session's)
    max_offset_mm: float = (
        30.0  # a take further than this from the commanded pose is the wrong take
    )
    max_attempts: int = 3
    max_augment_rounds: int = 2
    max_extra_poses: int = 12
    trust: TrustLimits = field(default_factory=TrustLimits)


@dataclass(frozen=True)
class WizardOutcome:
    state: WizardState
    identification: Identification | None
    profile: MachineProfile | None
    profile_path: Path | None
    session: Path


def copy_take(source: Path, target: Path) -> None:
    """Copy a take file, or a take folder of pictures, crash-safely (a temporary name first)."""
    if source.is_dir():
        tmp = target.with_name(target.name + ".tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(source, tmp)
        shutil.rmtree(target, ignore_errors=True)
        tmp.rename(target)
        return
    with atomic_open(target, "wb") as out, open(source, "rb") as src:
        shutil.copyfileobj(src, out)


def validate_take(
    path: Path,
    mocap: MocapConfig,
    pose: np.ndarray,
    max_offset_mm: float,
    history: list[tuple[float, TakeStatistics]] | None = None,
) -> TakeMeasurement:
    """Read and judge a take now (markers, base fit, gaps, spread, drift; its noise pooled
    with ``history``, to which it is added when sound), and check it was taken at this pose;
    raises :class:`TakeRejected` naming the problem."""
    series = prepare_take(read_take(path, mocap.format), mocap)
    measurement, first = judge_in_session(series, mocap.acceptance, history or ())
    offset = float(np.linalg.norm(measurement.point - pose))
    if offset > max_offset_mm:
        raise TakeRejected(
            f"the effector measures {offset:.1f} mm from the commanded pose ({', '.join(f'{v:.1f}' for v in pose)}); "
            f"limit {max_offset_mm:g} mm: is this the take of another pose?",
            source=str(path),
            reason="wrong-pose",
        )
    if history is not None:
        history.append((series.rate_hz, first))
    return measurement


class CalibrationWizard:
    """Plan (or resume), visit every pose, record and judge takes, identify, add poses if refused."""

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
        camera: CameraConfig | None = None,
        intrinsics: Intrinsics | None = None,
        candidates: np.ndarray | None = None,
    ):
        self.dir = Path(session_dir)
        self.profile = profile
        self.model = MachineModel.from_profile(profile)
        self.device = device
        self.takes = takes
        self.options = options
        self.log = log
        self.candidates = candidates  # poses the measuring system can see (None: all)
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
                candidates=candidates,
            )
            write_text_atomic(plan_path, plan_csv(self.plan))
        if not (self.dir / POSES_FILE).is_file():
            write_text_atomic(self.dir / POSES_FILE, ",".join(POSE_COLUMNS + EXTRA_COLUMNS) + "\n")
        config = None
        if not (self.dir / "session.toml").is_file():
            if mocap is None and camera is None:
                raise InputError(
                    "a new session needs the motion-capture configuration (markers) "
                    "or the camera's ([camera]: boards)",
                    source=str(self.dir),
                )
            config = SessionConfig(
                session={"profile": profile_ref or profile.name},  # type: ignore[arg-type]
                mocap=mocap,
                camera=camera,
            )
            if camera is not None and camera.intrinsics and intrinsics is not None:
                write_text_atomic(self.dir / camera.intrinsics, intrinsics_toml(intrinsics))
        self.writer = SessionWriter(self.dir, config)
        self.intrinsics = intrinsics
        table = read_poses(self.dir / POSES_FILE)
        rounds = max((self.plan.round_of(i) for i in range(len(self.plan.poses))), default=0)
        self.state = dataclasses.replace(
            resume_state(self.plan, table.extra.get("plan_pose", ()), options.max_attempts, rounds),
            max_rounds=options.max_augment_rounds,
        )
        self._t_offset = float(np.max(table.t_s, initial=0.0))
        self._t0: float | None = None  # device time of the first settle of this run
        self._t = self._t_offset
        self._steps: np.ndarray | None = None
        self._history: list[tuple[float, TakeStatistics]] = []
        self.identification: Identification | None = None
        self.calibrated: MachineProfile | None = None

    # --------------------------------------------------------------- steps
    def step(self) -> Action:
        """Carry out the next action; returns the action it carried out."""
        action = self.state.next_action()
        match action:
            case MoveTo():
                self._move(action)
            case RecordTake():
                self._record(action)
            case IdentifyStep():
                self._identify()
            case PlanMore():
                self._plan_more(action)
            case Finished():
                pass
        return action

    def run(self) -> WizardOutcome:
        while not isinstance(self.step(), Finished):
            pass
        return self.outcome

    def _label(self, i: int) -> str:
        p = self.plan.poses[i]
        return f"pose {i + 1}/{len(self.plan.poses)} ({self.plan.roles[i]}) at ({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f})"

    def _move(self, action: MoveTo) -> None:
        again = f" again (attempt {self.state.attempts + 1})" if self.state.attempts else ""
        self.log(f"moving to {self._label(action.index)}{again}")
        steps, t = self.device.visit(action.waypoints)
        self._steps = np.asarray(steps, dtype=np.int64)[:3]
        if self._t0 is None:
            self._t0 = float(t)
        self._t = self._t_offset + float(t) - self._t0
        self.state = self.state.moved(action.index)

    def _record(self, action: RecordTake) -> None:
        i = action.index
        self.log(f"{self._label(i)} has settled: record a take")
        path = Path(self.takes.take_for(i, self.plan.poses[i], action.attempt))
        try:
            summary = self._judge(path, self.plan.poses[i])
        except InputError as exc:  # TakeRejected or an unreadable file
            reason = exc.reason if isinstance(exc, TakeRejected) else "unreadable"
            self.state = self.state.rejected(i, f"{reason}: {exc}")
            if i in self.state.skipped:
                self.log(
                    f"{self._label(i)} skipped after {self.options.max_attempts} refused takes: {exc}"
                )
            else:
                self.log(f"take refused ({reason}: {exc}); moving to the pose again for a new take")
            return
        if self._steps is None:
            raise CdprError("internal: a take was recorded before any move")
        rel = f"takes/pose_{self.writer.next_pose:04d}{'' if path.is_dir() else path.suffix}"
        copy_take(path, self.dir / rel)  # the take exactly as recorded
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
        self.log(f"recorded {self._label(i)}: {summary}")

    def _judge(self, path: Path, pose: np.ndarray) -> str:
        """Judge a take now (raises on a refused one); a one-line summary."""
        camera = self.writer.config.camera
        if camera is not None:
            intrinsics = self.intrinsics or session_intrinsics(self.dir, camera)[0]
            c = judge_camera_take(
                path,
                camera.setup(),
                intrinsics,
                pose,
                self.options.max_offset_mm,
                camera.acceptance.min_valid_fraction,
            )
            return f"{c.n_used}/{c.n_frames} frames, spread {c.spread_mm:.3f} mm"
        m = validate_take(
            path,
            self.writer.config.motion_capture,
            pose,
            self.options.max_offset_mm,
            self._history,
        )
        s = m.stats
        return (
            f"sigma {m.sigma_mm:.4f} mm, drift {s.drift_total_mm:.3f} mm, "
            f"spread {m.spread_mm:.3f} mm, {m.n_frames_used} frames"
            + (f" ({'; '.join(m.warnings)})" if m.warnings else "")
        )

    def _identify(self) -> None:
        self.log("identifying the 12 parameters")
        result = identify_session(
            self.dir,
            self.model,
            noise_floor_mm=self.options.noise_floor_mm,
            limits=self.options.trust,
            refine=self.options.refine,
            alpha=self.options.alpha,
        )
        if result.verification is not None:
            self.log(result.verification.text())
        write_text_atomic(self.dir / REPORT_FILE, dumps(result.to_json(), indent=2) + "\n")
        self.identification = result
        if result.ok:
            self.calibrated = calibrated_profile(
                self.profile, result, session=str(self.dir.resolve())
            )
            save_profile(self.calibrated, self.dir / PROFILE_FILE)
            self.log(
                f"trusted: predicted workspace error RMS {result.predicted_workspace_rms_mm:.3f} mm, "
                f"max {result.predicted_workspace_max_mm:.3f} mm"
            )
        else:
            gate = result.trust is not None and bool(result.trust.refusals)
            who = "the trust gate" if gate or result.verification is None else "the verification"
            self.log(f"{who} refused: " + "; ".join(result.problems()))
        self.state = self.state.identified_as(result.ok, "; ".join(result.problems()))

    def _plan_more(self, action: PlanMore) -> None:
        result = self.identification
        recorded = sorted(self.state.recorded)
        fit_rows = [i for i in recorded if self.plan.roles[i] == "fit"]
        sigma = 0.05
        if result is not None and result.noise is not None:
            factor = result.trust.variance_factor if result.trust else 1.0
            sigma = result.noise.typical_mm * float(
                np.sqrt(max(factor, 1.0) if np.isfinite(factor) else 1.0)
            )
        extra = extra_poses(
            self.model,
            self.plan.poses[fit_rows],
            sigma,
            limits=self.options.trust,
            has_check_poses=any(self.plan.roles[i] == "check" for i in recorded),
            max_extra=self.options.max_extra_poses,
            candidates=self.candidates,
        )
        plan = extend_plan(self.plan, self.model, extra.poses) if len(extra.poses) else self.plan
        if len(extra.poses):
            write_text_atomic(self.dir / PLAN_FILE, plan_csv(plan))
            self.log(
                f"planned {len(extra.poses)} more pose(s) (round {action.round}; predicted workspace "
                f"error with them: RMS {extra.predicted_rms_mm:.3f} mm, max {extra.predicted_max_mm:.3f} mm)"
            )
        self.plan = plan
        self.state = self.state.augmented(plan)

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
