"""The lab side of the controller: the calibration wizard and the diagnosis workflow."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from cdprhost.tui.control.link_flow import ControllerBase
from cdprhost.tui.control.views import ConsoleLine, PoseView
from cdprhost.tui.state import DiagnoseView


class LabFlow(ControllerBase):
    # ------------------------------------------------------------ calibrate
    def _calibration(
        self, work: Callable[[], Any], done: Callable[[Any], None], stage: str, busy: str = ""
    ) -> None:
        if self.backend.calibration is None:
            self.update(
                calibration=replace(
                    self.state.calibration,
                    stage="error",
                    message=getattr(
                        self.backend, "calibration_refusal", "calibration wizard not available"
                    ),
                )
            )
            return
        self.update(calibration=replace(self.state.calibration, stage=stage, message=""), busy=busy)

        def finished(result: Any) -> None:
            self.update(busy="")
            done(result)

        def fail(exc: BaseException) -> None:
            poses = tuple(
                replace(p, status="planned") if p.status == "moving" else p
                for p in self.state.calibration.poses
            )
            self.update(
                busy="",
                calibration=replace(
                    self.state.calibration,
                    poses=poses,
                    stage="error",
                    message=str(exc) or type(exc).__name__,
                ),
            )

        self.background("calibration", work, finished, fail, exclusive=True)

    def plan_calibration(
        self,
        n_fit: int,
        n_check: int,
        session_dir: str | None,
        mocap_config: str | None = None,
        camera: str | None = None,
        intrinsics: str | None = None,
    ) -> None:
        """Plan the poses; with ``camera`` it takes the pictures instead of motion capture
        (``intrinsics``: its camera.toml)."""
        calib = self.backend.calibration
        if calib is None:
            self._calibration(lambda: None, lambda _: None, "planning")
            return
        extra = {"camera": camera, "intrinsics": intrinsics} if camera else {}
        self._calibration(
            lambda: calib.plan(n_fit, n_check, session_dir, mocap_config, **extra),
            lambda view: self.update(calibration=view),
            "planning",
            "planning poses",
        )

    def _put_pose(self, pose: PoseView, stage: str, message: str = "") -> None:
        cal = self.state.calibration
        poses = tuple(pose if p.index == pose.index else p for p in cal.poses)
        self.update(
            calibration=replace(cal, poses=poses, current=pose.index, stage=stage, message=message)
        )

    def awaiting_take(self) -> PoseView | None:
        """The settled pose that needs a (new) take, if any."""
        return next(
            (p for p in self.state.calibration.poses if p.status in ("settled", "rejected")), None
        )

    def next_pose(self) -> PoseView | None:
        """The next pose to move to (none while a pose awaits its take)."""
        if self.awaiting_take() is not None:
            return None
        return next((p for p in self.state.calibration.poses if p.status == "planned"), None)

    def move_to_pose(self) -> None:
        pose = self.next_pose()
        if pose is None or self.state.busy:
            return
        calib = self.backend.calibration
        if calib is None:
            return
        self._put_pose(replace(pose, status="moving"), "measuring")
        self._calibration(
            lambda: calib.move_to(pose),
            lambda p: self._put_pose(p, "measuring", f"pose {p.index} settled: record a take"),
            "measuring",
            f"moving to pose {pose.index}",
        )

    def ingest_take(self, take_path: str) -> None:
        pose = self.awaiting_take()
        calib = self.backend.calibration
        if pose is None or calib is None:
            return
        self._calibration(
            lambda: calib.ingest(pose, take_path),
            lambda p: self._put_pose(p, "measuring", p.detail),
            "measuring",
            "checking the take",
        )

    def identify(self) -> None:
        calib = self.backend.calibration

        def done(result: Any) -> None:
            self.update(
                calibration=replace(self.state.calibration, stage="done", result=result, message="")
            )

        self._calibration(
            calib.identify if calib else (lambda: None), done, "identifying", "identifying"
        )

    # -------------------------------------------------------------- diagnose
    def diagnose(self, session_dir: str) -> None:
        self.update(diagnose=DiagnoseView(session_dir=session_dir, running=True))

        def done(view: Any) -> None:
            self.update(diagnose=DiagnoseView(session_dir, False, view))

        def fail(exc: BaseException) -> None:
            self.update(
                diagnose=DiagnoseView(session_dir, False, None, str(exc) or type(exc).__name__)
            )

        self.background(
            "diagnose", lambda: self.backend.diagnose(session_dir), done, fail, exclusive=True
        )

    def write_diagnosed_profile(self) -> None:
        """Write the profile the last diagnosis improved, asked first (where, and whether a
        shipped profile is kept); refused with the reason when it did not improve it."""
        plan_of = getattr(self.backend, "diagnosed_write_plan", None)
        if plan_of is None:
            self.app.notify("this backend cannot write profiles", severity="warning")
            return
        plan = plan_of()
        if plan.refused:
            self.app.notify(f"profile not written: {plan.refused}", severity="warning")
            return

        def write() -> None:
            def done(path: Any) -> None:
                text = f"wrote the improved profile to {path}"
                self.say(ConsoleLine("notice", text, self.app.wall_clock()))
                self.app.notify(text, title="diagnose")

            def fail(exc: BaseException) -> None:
                text = f"profile not written: {exc.strerror if isinstance(exc, OSError) else exc}"
                self.say(ConsoleLine("error", text, self.app.wall_clock()))
                self.app.notify(text, title="diagnose", severity="error")

            self.background("write profile", self.backend.write_diagnosed_profile, done, fail)  # type: ignore[attr-defined]

        self.app.confirm(plan.question(), write)
