"""Turns UI requests into backend calls on worker threads, and results into state.

Every blocking backend call runs in a Textual thread worker. Its result comes
back through ``App.call_from_thread`` and is applied to the app's single
:class:`~cdprhost.tui.state.UiState` in the UI thread; job events go through
the :class:`~cdprhost.tui.control.pump.EventPump`. Nothing here draws.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from cdprhost.job.state import JobSnapshot, JobState, StateChanged
from cdprhost.tui.control.backend import Backend, JobHandle
from cdprhost.tui.control.jog import check_jog, jog_target
from cdprhost.tui.control.views import PoseView
from cdprhost.tui.state import ConnectionView, DiagnoseView, FileView, UiState

if TYPE_CHECKING:  # pragma: no cover
    from cdprhost.tui.app import CdprApp

TEMPERATURE_HISTORY = 600


class Controller:
    def __init__(self, app: CdprApp, backend: Backend):
        self.app = app
        self.backend = backend
        self._job: JobHandle | None = None
        self._job_lock = threading.Lock()

    # ------------------------------------------------------------ plumbing
    @property
    def state(self) -> UiState:
        return self.app.state

    def update(self, **changes: Any) -> None:
        """Replace fields of the UI state (UI thread only)."""
        self.app.state = replace(self.app.state, **changes)

    def background(
        self,
        name: str,
        work: Callable[[], Any],
        done: Callable[[Any], None],
        fail: Callable[[BaseException], None] | None = None,
        *,
        exclusive: bool = False,
    ) -> None:
        """Run ``work`` in a thread worker; ``done``/``fail`` then run in the UI thread."""
        app = self.app

        def body() -> None:
            try:
                result = work()
            except BaseException as exc:  # noqa: BLE001 - every failure is shown, none kills the UI
                app.call_later_safe(fail or self._report, exc)
                return
            app.call_later_safe(done, result)

        app.run_worker(
            body, name=name, group=name, thread=True, exclusive=exclusive, exit_on_error=False
        )

    def _report(self, exc: BaseException) -> None:
        self.app.notify(str(exc) or type(exc).__name__, title="error", severity="error", timeout=8)

    # ---------------------------------------------------------- connection
    def connect(self, port: str, baud: int) -> None:
        self.update(connection=ConnectionView(status="connecting", port=port, baud=baud))

        def done(identity: tuple[tuple[str, str], ...]) -> None:
            self.update(
                connection=ConnectionView(
                    "connected", port, baud, tuple(identity), "", self.backend.link_health()
                )
            )
            self.refresh_device()

        def fail(exc: BaseException) -> None:
            self.update(
                connection=ConnectionView("error", port, baud, (), str(exc) or type(exc).__name__)
            )
            self._report(exc)

        self.background(
            "connect", lambda: self.backend.connect(port, baud), done, fail, exclusive=True
        )

    def disconnect(self) -> None:
        conn = self.state.connection

        def done(_: Any) -> None:
            self.update(
                connection=ConnectionView("disconnected", conn.port, conn.baud),
                device=None,
                jog=None,
            )

        self.background("connect", self.backend.disconnect, done, exclusive=True)

    def poll_health(self) -> None:
        """Non-blocking: copy the link counters into the state when they changed."""
        conn = self.state.connection
        if conn.status != "connected":
            return
        health = self.backend.link_health()
        if health != conn.health:
            self.update(connection=replace(conn, health=health))

    def refresh_device(self) -> None:
        if not self.state.connected or self.state.job_active or self.state.busy:
            return

        def done(status: Any) -> None:
            if status is not None and not self.state.job_active:
                self._device(status)

        def fail(exc: BaseException) -> None:  # the link died (device reset, port gone): say so
            conn = self.state.connection
            if conn.status == "connected" and not self.state.job_active:
                self.update(
                    connection=replace(conn, status="error", error=str(exc) or type(exc).__name__)
                )

        self.background("status", self.backend.device_status, done, fail, exclusive=True)

    def _device(self, status: Any) -> None:
        hist = self.state.device_temps
        if status.hotend is not None and status.bed is not None:
            hist = (*hist[-(TEMPERATURE_HISTORY - 1) :], (status.hotend, status.bed))
        self.update(device=status, device_temps=hist)

    # ----------------------------------------------------------------- print
    def open_file(self, path: str) -> None:
        self.update(file=FileView(path=path, checking=True))

        def done(view: Any) -> None:
            if self.state.file.path == path:
                self.update(file=FileView(path=path, preflight=view))

        def fail(exc: BaseException) -> None:
            if self.state.file.path == path:
                self.update(file=FileView(path=path, error=str(exc) or type(exc).__name__))

        self.background(
            "preflight", lambda: self.backend.preflight(path), done, fail, exclusive=True
        )

    def start(self, resume_from_layer: int | None = None) -> None:
        path = self.state.file.path
        if not path or self.state.job_active:
            return
        job_id = self.state.job_id + 1
        self.update(job=JobSnapshot(), job_id=job_id, job_path=path, device=None, jog=None)
        sink = self.app.pump.sink(job_id)

        def work() -> Any:
            job = self.backend.make_job(path, sink, resume_from_layer)
            with self._job_lock:
                self._job = job
            try:
                return job.run()
            finally:
                with self._job_lock:
                    self._job = None

        def done(result: Any) -> None:
            self.app.job_finished(job_id, result, None)
            self.probe_connection()

        def fail(exc: BaseException) -> None:
            if not self.state.job.state.finished:  # the runner died without saying so
                sink(StateChanged(JobState.FAILED, str(exc) or type(exc).__name__))
            self.app.job_finished(job_id, None, exc)
            self.probe_connection()

        self.background("job", work, done, fail)

    def probe_connection(self) -> None:
        """After a job: is the link alive? (A job may have re-opened it, or lost it.)"""
        conn = self.state.connection
        if conn.status not in ("connected", "error") or not self.backend.connected():
            return

        def done(status: Any) -> None:
            self.update(connection=replace(self.state.connection, status="connected", error=""))
            if status is not None:
                self._device(status)

        def fail(exc: BaseException) -> None:
            self.update(
                connection=replace(
                    self.state.connection, status="error", error=str(exc) or type(exc).__name__
                )
            )

        self.background("status", self.backend.device_status, done, fail, exclusive=True)

    def _request(self, what: str) -> None:
        with self._job_lock:
            job = self._job
        if job is not None:
            getattr(job, f"request_{what}")()

    def pause(self) -> None:
        self._request("pause")

    def resume(self) -> None:
        self._request("resume")

    def cancel(self) -> None:
        self._request("cancel")

    # ------------------------------------------------------------------- jog
    def preview_jog(self, axis: str, step_mm: float) -> None:
        """Set the pending jog target from the last target (or the device position) and check it."""
        base = self.state.jog.target if self.state.jog is not None else self._position()
        if base is None:
            self.app.notify("position unknown: connect and home first", severity="warning")
            return
        target = jog_target(base, axis, step_mm)
        self.update(jog=check_jog(self.backend.model, self._position(), target))

    def clear_jog(self) -> None:
        self.update(jog=None)

    def _position(self) -> tuple[float, float, float] | None:
        dev = self.state.device
        return None if dev is None else dev.position

    def _device_op(self, label: str, work: Callable[[], Any]) -> None:
        if self.state.busy or self.state.job_active or not self.state.connected:
            return
        self.update(busy=label)

        def done(status: Any) -> None:
            self.update(busy="", jog=None)
            if status is not None:
                self._device(status)

        def fail(exc: BaseException) -> None:
            self.update(busy="")
            self._report(exc)

        self.background("device", work, done, fail)

    def jog_go(self) -> None:
        check = self.state.jog
        if check is None or not check.ok:
            return
        self._device_op(
            f"moving to ({check.target[0]:.1f}, {check.target[1]:.1f}, {check.target[2]:.1f})",
            lambda: self.backend.jog_to(check.target),
        )

    def home(self) -> None:
        self._device_op("homing", self.backend.home)

    def motors_off(self) -> None:
        self._device_op("motors off", self.backend.motors_off)

    def set_heaters(self, hotend_c: float, bed_c: float) -> None:
        self._device_op("heaters", lambda: self.backend.set_heaters(hotend_c, bed_c))

    # ------------------------------------------------------------ calibrate
    def _calibration(
        self, work: Callable[[], Any], done: Callable[[Any], None], stage: str, busy: str = ""
    ) -> None:
        if self.backend.calibration is None:
            self.update(
                calibration=replace(
                    self.state.calibration,
                    stage="error",
                    message="calibration wizard not available",
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

    def plan_calibration(self, n_fit: int, n_check: int, session_dir: str | None) -> None:
        calib = self.backend.calibration
        self._calibration(
            lambda: calib.plan(n_fit, n_check, session_dir),
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
        self._put_pose(replace(pose, status="moving"), "measuring")
        self._calibration(
            lambda: calib.move_to(pose),
            lambda p: self._put_pose(p, "measuring", f"pose {p.index} settled: record a take"),
            "measuring",
            f"moving to pose {pose.index}",
        )

    def ingest_take(self, take_path: str) -> None:
        pose = self.awaiting_take()
        if pose is None:
            return
        calib = self.backend.calibration
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
