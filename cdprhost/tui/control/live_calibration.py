"""The calibration wizard (:mod:`cdprhost.calibration.wizard`) behind the calibrate screen.

The wizard's own state machine decides what comes next; this adapter lets the
screen trigger each step (move, ingest a take, identify) and reports the
outcome as views. The take of a pose is the file the user names; with the
embedded simulated device and virtual motion capture the newest take in the
mocap folder is offered. The device is its host's (:class:`WizardHost`): the machine in this
process (``--in-process``), or the printer service's device session; the wizard's planning,
judging and fitting run here either way.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import numpy as np

from cdprhost.errors import CdprError, InputError
from cdprhost.kinematics import MachineModel
from cdprhost.profile import MachineProfile
from cdprhost.tui.control.views import CalibrationView, IdentificationView, ParameterRow, PoseView

DEFAULT_SESSION = "calibration-session"
SETTLE_S = 0.5  # at rest this long after each move before a take


class WizardHost(Protocol):
    """What the wizard needs of the UI's backend."""

    profile: MachineProfile
    model: MachineModel
    profile_name: str

    def wizard_device(self, settle_s: float) -> Any:
        """The connected machine as the wizard's device (``visit``)."""
        ...

    def virtual_mocap(self) -> str | None:
        """The folder of the virtual motion capture's takes, which watches the embedded
        simulated device from now on (None: none watches)."""
        ...

    def simulated_camera(self, size: tuple[int, int]) -> Any:
        """The simulated camera (a capture) of ``size`` pixels, watching the embedded
        simulated device; InputError when the UI is not connected to it."""
        ...


class _GivenTake:
    """TakeSource that hands the wizard the file the user picked."""

    def __init__(self) -> None:
        self.path: Path | None = None

    def take_for(self, index: int, pose: np.ndarray, attempt: int) -> Path:
        if self.path is None:
            raise InputError("no take file given")
        return self.path


def _point(p: Any) -> tuple[float, float, float]:
    return tuple(float(v) for v in np.asarray(p, dtype=float).reshape(3))  # type: ignore[return-value]


def identification_view(result: Any, profile_path: str = "") -> IdentificationView:
    """An :class:`~cdprhost.calibration.identification.Identification` as rows and totals."""
    before = np.concatenate([result.nominal.outlets.ravel(), result.nominal.initial_lengths])
    after = np.concatenate([result.geometry.outlets.ravel(), result.geometry.initial_lengths])
    rows = tuple(
        ParameterRow(
            name,
            float(before[i]),
            float(after[i]),
            float(result.stderr[i]) if np.isfinite(result.stderr[i]) else None,
            float(result.ci95[i][0]) if np.isfinite(result.ci95[i][0]) else None,
            float(result.ci95[i][1]) if np.isfinite(result.ci95[i][1]) else None,
        )
        for i, name in enumerate(result.names)
    )
    warnings = tuple(result.problems())
    if result.correlations:
        worst = max(result.correlations, key=lambda c: abs(c[2]))
        warnings += (
            (
                f"{len(result.correlations)} parameter pair(s) correlate above 0.95 "
                f"(strongest {worst[0]} / {worst[1]}: {worst[2]:.3f}); "
                "check poses tell how well it predicts"
            ),
        )
    return IdentificationView(
        rows,
        float(result.rms_before_mm),
        float(result.rms_after_mm),
        int(result.iterations),
        int(result.poses_used),
        result.check_rms_before_mm,
        result.check_rms_after_mm,
        warnings,
        profile_path,
        None if result.trust is None else bool(result.ok),
        None if result.trust is None else float(result.predicted_workspace_rms_mm),
        None if result.trust is None else float(result.predicted_workspace_max_mm),
    )


class LiveCalibration:
    """``mocap_dir``: where the takes to offer appear (default: the virtual motion capture's)."""

    def __init__(self, backend: WizardHost, *, mocap_dir: str | None = None):
        self.backend = backend
        self.given_mocap_dir = mocap_dir
        self.mocap_dir = mocap_dir
        self.wizard: Any = None
        self.source = _GivenTake()
        self.camera = ""  # the camera that takes the pictures ("": motion capture takes)
        self.messages: list[str] = []

    # --------------------------------------------------------------- views
    def _view(self, stage: str, message: str = "", current: int | None = None) -> CalibrationView:
        w = self.wizard
        state, plan = w.state, w.plan
        poses = []
        for i, p in enumerate(plan.poses):
            status = (
                "take ok" if i in state.recorded else "skipped" if i in state.skipped else "planned"
            )
            detail = ""
            if i == state.at and status == "planned":
                status = "settled"
                detail = state.last_problem or ""
            poses.append(PoseView(i + 1, _point(p), str(plan.roles[i]), status, detail))
        return CalibrationView(
            stage,
            tuple(poses),
            current,
            str(w.dir),
            tuple(sorted(plan.indices.items())),
            None,
            message,
            camera=self.camera,
        )

    def _pose(self, index: int) -> PoseView:
        return self._view("measuring").poses[index - 1]

    def _log(self, text: str) -> None:
        self.messages.append(text)

    # ---------------------------------------------------------------- steps
    def plan(
        self,
        n_fit: int,
        n_check: int,
        session_dir: str | None,
        mocap_config: str | None = None,
        camera: str | None = None,
        intrinsics: str | None = None,
    ) -> CalibrationView:
        """A new session (its markers from ``mocap_config``, a TOML file with the ``[mocap]``
        table, checked before anything is written) or the one in ``session_dir``; with
        ``camera`` (:mod:`~cdprhost.tui.control.live_camera`) the camera takes pictures
        instead (``mocap_config``: its ``[camera]`` boards; ``intrinsics``: its camera.toml)."""
        from cdprhost.calibration.session import mocap_for_session
        from cdprhost.calibration.wizard import CalibrationWizard, WizardOptions

        b = self.backend
        folder = session_dir or DEFAULT_SESSION
        if camera:
            from cdprhost.tui.control.live_camera import FRAMES, camera_setup

            setup = camera_setup(
                camera,
                Path(folder),
                b.model,
                sim_camera=b.simulated_camera,
                config_path=mocap_config,
                intrinsics_path=intrinsics,
                log=self._log,
            )
            takes = setup.takes(Path(folder), FRAMES, self._log)
            device = b.wizard_device(SETTLE_S)
            self.camera = camera
            self.wizard = CalibrationWizard(
                folder,
                b.profile,
                device,
                takes,
                mocap=None,
                options=WizardOptions(n_poses=n_fit, n_check=n_check),
                log=self._log,
                profile_ref=b.profile_name,
                camera=setup.config,
                intrinsics=setup.intrinsics,
                candidates=setup.candidates(takes, b.model, n_fit + n_check),
            )
            return self._view("planned", self.messages[-1] if self.messages else "")
        self.camera = ""
        device = b.wizard_device(SETTLE_S)
        virtual_dir = b.virtual_mocap()
        self.mocap_dir = self.given_mocap_dir or virtual_dir
        virtual = None
        if virtual_dir is not None:
            from cdprhost.sim.virtual_mocap import mocap_config as virtual_config

            virtual = virtual_config(b.profile_name).mocap
        mocap = mocap_for_session(folder, mocap_config, virtual)
        self.wizard = CalibrationWizard(
            folder,
            b.profile,
            device,
            self.source,
            mocap=mocap,
            options=WizardOptions(n_poses=n_fit, n_check=n_check),
            log=self._log,
            profile_ref=b.profile_name,
        )
        return self._view("planned", self.messages[-1] if self.messages else "")

    def _require(self, kind: type, index: int | None = None) -> Any:
        if self.wizard is None:
            raise CdprError("plan the poses first")
        action = self.wizard.state.next_action()
        if not isinstance(action, kind) or (
            index is not None and getattr(action, "index", None) != index - 1
        ):
            raise CdprError(f"the wizard expects {type(action).__name__} next, not {kind.__name__}")
        return action

    def move_to(self, pose: PoseView) -> PoseView:
        from cdprhost.calibration.wizard import MoveTo

        self._require(MoveTo, pose.index)
        seen = self._takes()
        self.wizard.step()
        new = sorted(set(self._takes()) - set(seen), key=lambda p: p.stat().st_mtime)
        view = self._pose(pose.index)
        return PoseView(
            view.index,
            view.point,
            view.role,
            "settled",
            "settled: record a take",
            take=str(new[-1]) if new else "",
        )

    def _takes(self) -> list[Path]:
        if not self.mocap_dir or not Path(self.mocap_dir).is_dir():
            return []
        return [p for p in Path(self.mocap_dir).iterdir() if p.is_file()]

    def ingest(self, pose: PoseView, take_path: str) -> PoseView:
        from cdprhost.calibration.wizard import RecordTake

        self._require(RecordTake, pose.index)
        self.source.path = Path(take_path)  # (a camera takes its pictures itself)
        before = len(self.messages)
        self.wizard.step()
        view = self._pose(pose.index)
        if view.status == "take ok":
            detail = (
                self.messages[-1].split(": ", 1)[-1] if len(self.messages) > before else "recorded"
            )
            return PoseView(view.index, view.point, view.role, "take ok", detail)
        problem = self.wizard.state.last_problem or "rejected"
        status = "skipped" if view.status == "skipped" else "rejected"
        return PoseView(view.index, view.point, view.role, status, problem)

    def identify(self) -> IdentificationView:
        from cdprhost.calibration.wizard import IdentifyStep, PlanMore

        self._require(IdentifyStep)
        self.wizard.step()
        if isinstance(self.wizard.state.next_action(), PlanMore):
            self.wizard.step()  # the gate refused: extra poses join the plan, to be measured next
        outcome = self.wizard.outcome
        if outcome.identification is None:
            raise CdprError("identification did not run")
        return identification_view(outcome.identification, str(outcome.profile_path or ""))
