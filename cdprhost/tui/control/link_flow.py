"""The controller's base: worker plumbing, the link, device operations and the console.

Every blocking backend call runs in a Textual thread worker. Its result comes
back through ``App.call_from_thread`` and is applied to the app's single
:class:`~cdprhost.tui.state.UiState` in the UI thread; job events go through
the :class:`~cdprhost.tui.control.pump.EventPump`. Nothing here draws.

The controller (:mod:`.controller`) is one object in three parts: this module,
:mod:`.print_flow` (files, print jobs, resume, history) and :mod:`.lab_flow` (calibration
and diagnosis).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from cdprhost.motion.override import MAX_PERCENT, MIN_PERCENT
from cdprhost.tui.control.backend import EMBEDDED, Backend, JobHandle
from cdprhost.tui.control.console import ConsoleError, parse_command
from cdprhost.tui.control.host import ControllerHost
from cdprhost.tui.control.jog import check_jog, jog_target
from cdprhost.tui.control.live_console import status_lines, temperature_line
from cdprhost.tui.control.views import ConsoleLine, DeviceStatusView
from cdprhost.tui.state import CONSOLE_LINES, ConnectionView, UiState
from cdprhost.tui.tabs import screen_key

TEMPERATURE_HISTORY = 600
JOB_HEALTH_EVERY_S = 5.0  # while a job runs its own events carry the link health
RECONNECT_EVERY_S = 2.0  # a lost link asks the device again this often (it may come back)


class ControllerBase:
    def __init__(self, app: ControllerHost, backend: Backend):
        self.app = app
        self.backend = backend
        self._job: JobHandle | None = None
        self._job_lock = threading.Lock()
        # the overrides asked of the running job (keys step from there, not from what the
        # job has applied yet)
        self._overrides_asked: tuple[JobHandle, dict[str, float]] | None = None
        self._job_ended = threading.Event()  # set when the running job's ``run`` returned
        self._quitting = ""  # why the app quits once the job has stopped ("quit", "SIGTERM")
        self._finished_id = 0  # the last job whose end was handled
        self._health_at = float("-inf")
        self._reconnect_at = float("-inf")
        self._status_gen = 0  # a status asked before this job began or ended is not shown

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
                app.call_later_safe(fail or self.report, exc)
                return
            app.call_later_safe(done, result)

        app.run_worker(
            body, name=name, group=name, thread=True, exclusive=exclusive, exit_on_error=False
        )

    def report(self, exc: BaseException) -> None:
        self.app.notify(str(exc) or type(exc).__name__, title="error", severity="error", timeout=8)

    def say(self, *lines: ConsoleLine) -> None:
        """Add lines to the console (UI thread)."""
        if lines:
            self.update(console=(*self.state.console, *lines)[-CONSOLE_LINES:])

    # ---------------------------------------------------------- connection
    def connect(self, port: str, baud: int) -> None:
        simulated = port == EMBEDDED
        self.update(
            connection=ConnectionView(
                status="connecting", port=port, baud=baud, simulated=simulated
            )
        )

        def done(identity: tuple[tuple[str, str], ...]) -> None:
            self.update(
                connection=ConnectionView(
                    "connected",
                    port,
                    baud,
                    tuple(identity),
                    "",
                    self.backend.link_health(),
                    simulated,
                )
            )
            where = "the embedded simulated device (no hardware)" if simulated else port
            self.say(ConsoleLine("notice", f"connected to {where}", self.app.wall_clock()))
            if not self.adopt_running_job():
                self.refresh_device()
            self.connected_again()

        def fail(exc: BaseException) -> None:
            text = str(exc) or type(exc).__name__
            self.update(connection=ConnectionView("error", port, baud, (), text, None, simulated))
            self.say(
                ConsoleLine("error", f"cannot connect to {port}: {text}", self.app.wall_clock())
            )
            self.report(exc)

        self.background(
            "connect", lambda: self.backend.connect(port, baud), done, fail, exclusive=True
        )

    def connected_again(self) -> None:
        """Hook for the print flow: a new link (look for a resume point again)."""

    def adopt_running_job(self) -> bool:
        """Hook for the print flow: follow a print the device's service is running."""
        return False

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
        """Non-blocking: copy the link counters into the state when they changed. While a
        job runs, its events carry them to the print screen: the copy (for the link screen)
        is then made only every ``JOB_HEALTH_EVERY_S`` (each copy redraws the screen)."""
        conn = self.state.connection
        if conn.status != "connected":
            return
        now = self.app.clock()
        if self.state.job_active and now - self._health_at < JOB_HEALTH_EVERY_S:
            return
        health = self.backend.link_health()
        if health != conn.health:
            self._health_at = now
            self.update(connection=replace(conn, health=health))

    def refresh_device(self) -> None:
        if self.state.connection.status == "error" and not self.state.job_active:
            now = self.app.clock()  # lost (a frozen device): ask again, it may come back
            if now - self._reconnect_at >= RECONNECT_EVERY_S and self.backend.connected():
                self._reconnect_at = now
                self.recheck_link()
            return
        if not self.state.connected or self.state.job_active:
            return
        if self.adopt_running_job():  # started meanwhile by another front end (the page)
            return
        gen = self._status_gen
        if self.state.busy:  # homing, a jog, a heater wait: temperatures stay fresh
            self.background(
                "status-busy",
                self.backend.status_while_busy,
                lambda status: self._seen_while_busy(status, gen),
                lambda _exc: None,  # the operation itself reports a dead link
                exclusive=True,
            )
            return

        def done(status: Any) -> None:
            self.say(*self.backend.device_log())
            if status is not None and not self.state.job_active and gen == self._status_gen:
                self.device_seen(status)

        def fail(exc: BaseException) -> None:  # the link died (device reset, port gone): say so
            conn = self.state.connection
            self.say(*self.backend.device_log())
            if conn.status == "connected" and not self.state.job_active and gen == self._status_gen:
                text = str(exc) or type(exc).__name__
                self.update(connection=replace(conn, status="error", error=text))
                self.say(ConsoleLine("error", f"link lost: {text}", self.app.wall_clock()))

        self.background("status", self.backend.device_status, done, fail, exclusive=True)

    def recheck_link(self, then: Callable[[], None] | None = None) -> None:
        """Ask the device for its status: the link is "connected" again when it answers (after
        a job, an emergency stop, a cleared fault), "error" when it does not; ``then`` runs
        either way."""
        conn = self.state.connection
        if conn.status not in ("connected", "error") or not self.backend.connected():
            if then is not None:
                then()
            return

        def done(status: Any) -> None:
            self.update(connection=replace(self.state.connection, status="connected", error=""))
            self.say(*self.backend.device_log())  # "link back: ..." after a recovery
            if status is not None:
                self.device_seen(status)
            if then is not None:
                then()

        def fail(exc: BaseException) -> None:
            text = str(exc) or type(exc).__name__
            if self.state.connection.status == "connected":
                self.say(ConsoleLine("error", f"link lost: {text}", self.app.wall_clock()))
            self.update(connection=replace(self.state.connection, status="error", error=text))
            if then is not None:
                then()

        self.background("status", self.backend.device_status, done, fail, exclusive=True)

    def _seen_while_busy(self, status: DeviceStatusView | None, gen: int) -> None:
        if status is not None and self.state.busy and gen == self._status_gen:
            self.device_seen(status)

    def device_seen(self, status: DeviceStatusView) -> None:
        hist = self.state.device_temps
        if status.hotend is not None and status.bed is not None:
            hist = (*hist[-(TEMPERATURE_HISTORY - 1) :], (status.hotend, status.bed))
        self.update(device=status, device_temps=hist, temps_at=self.app.clock())

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

    def device_op(
        self, label: str, work: Callable[[], Any], then: Callable[[], None] | None = None
    ) -> None:
        why = self._refused_now()
        if why:  # said, never silently dropped ("jog h does nothing and says nothing")
            text = f"{label}: refused, nothing sent: {why}"
            self.say(ConsoleLine("error", text, self.app.wall_clock()))
            self.app.notify(text, severity="warning", timeout=8)
            return
        self.update(busy=label)

        def done(status: Any) -> None:
            self.update(busy="", jog=None)
            if status is not None:
                self.device_seen(status)
            if then is not None:
                then()

        def fail(exc: BaseException) -> None:
            self.update(busy="")
            self.say(ConsoleLine("error", f"{label}: {exc}", self.app.wall_clock()))
            self.report(exc)

        self.background("device", work, done, fail)

    def _refused_now(self) -> str:
        """Why a device operation cannot start now ("" when it can)."""
        state, conn = self.state, self.state.connection
        if state.job_active:
            return "a print is running"
        if state.busy:
            return f"busy ({state.busy}): try again when it is done"
        if conn.status == "error":
            where = screen_key("connection")
            return f"the link is lost ({conn.error}): it is asked again, or reconnect on {where}"
        if not state.connected:
            return f"not connected: connect on {screen_key('connection')}"
        return ""

    def jog_go(self) -> None:
        check = self.state.jog
        if check is None or not check.ok:
            return
        target = check.target
        self.device_op(
            f"moving to ({target[0]:.1f}, {target[1]:.1f}, {target[2]:.1f})",
            lambda: self.backend.jog_to(target),
        )

    def home(self) -> None:
        self.device_op("homing", self.backend.home)

    def motors_off(self) -> None:
        """Its own action, confirmed: the e-stop keeps the motors (the effector hangs on
        them), releasing them lets it drop."""
        self.app.confirm(
            "Release the motors? The effector hangs on them: support it first.",
            lambda: self.device_op("motors off", self.backend.motors_off),
        )

    def set_heaters(self, hotend_c: float, bed_c: float) -> None:
        self.device_op("heaters", lambda: self.backend.set_heaters(hotend_c, bed_c))

    # --------------------------------------------------------------- console
    def console_send(self, text: str) -> None:
        """Send one console line: answered from the running job's state while a print runs
        (only what does not move), else carried out on the device."""
        if not text.strip():
            return
        now = self.app.wall_clock()
        if self.state.job_active:
            self.say(ConsoleLine("sent", text.strip(), now), *self._answer_while_printing(text))
            return
        if self.state.connection.status not in ("connected", "error"):
            self.say(
                ConsoleLine("sent", text.strip(), now),
                ConsoleLine("error", "not connected: connect on the link screen first", now),
            )
            return
        if self.state.busy:
            self.say(
                ConsoleLine("sent", text.strip(), now),
                ConsoleLine("error", f"busy ({self.state.busy}): try again when it is done", now),
            )
            return
        sent = text.strip()
        self.update(busy=f"console: {sent}")
        self.say(ConsoleLine("sent", sent, now))  # at once, not when the command has ended

        def done(lines: list[ConsoleLine]) -> None:
            self.update(busy="")
            echo = next((i for i, c in enumerate(lines) if c.kind == "sent"), None)
            if echo is not None and lines[echo].text.strip() == sent:
                lines = lines[:echo] + lines[echo + 1 :]
            self.say(*lines)
            self.recheck_link()

        def fail(exc: BaseException) -> None:
            self.update(busy="")
            self.say(ConsoleLine("error", str(exc) or type(exc).__name__, self.app.wall_clock()))

        self.background("device", lambda: self.backend.console(text), done, fail)

    def emergency_stop(self) -> None:
        """Stop now, bypassing the queue (also while a print runs: through the job, which then
        ends with its resume point). The device's answer goes to the console and a
        notification; then the device is read again (temperatures, state)."""
        with self._job_lock:
            job = self._job
        stop = getattr(job, "emergency_stop", None) if job is not None else None
        work: Callable[[], Any] = stop if stop is not None else self.backend.emergency_stop
        self.say(ConsoleLine("sent", "M112 (emergency stop key)", self.app.wall_clock()))

        def done(answered: Any) -> None:
            if answered:
                text = (
                    "EMERGENCY STOP: the device confirmed; motion stopped, heaters off, "
                    "motors held (releasing them is its own action); M999 in the console "
                    "clears the stop"
                )
            else:
                text = (
                    "EMERGENCY STOP sent but the device did not confirm: check the machine "
                    "(cut its power if it still moves)"
                )
            self.say(ConsoleLine("notice" if answered else "error", text, self.app.wall_clock()))
            self.app.notify(
                text,
                title="emergency stop",
                severity="warning" if answered else "error",
                timeout=20,
            )
            self.recheck_link()

        def fail(exc: BaseException) -> None:
            text = f"EMERGENCY STOP failed: {exc or type(exc).__name__}: cut the machine's power"
            self.say(ConsoleLine("error", text, self.app.wall_clock()))
            self.app.notify(text, title="emergency stop", severity="error", timeout=30)
            self.recheck_link()

        self.background("estop", work, done, fail)

    def _answer_while_printing(self, text: str) -> list[ConsoleLine]:
        now = self.app.wall_clock()
        try:
            cmd = parse_command(text)
        except ConsoleError as exc:
            return [ConsoleLine("error", str(exc), now)]
        job = self.state.job
        if cmd.op == "temps" and job.temperatures is not None:
            t = job.temperatures
            view = DeviceStatusView(
                hotend=t.hotend, bed=t.bed, hotend_target=t.hotend_target, bed_target=t.bed_target
            )
            return [ConsoleLine("reply", temperature_line(view), now)]
        if cmd.op == "position":
            view = DeviceStatusView(steps=job.steps, position=job.position)
            bed = self.backend.profile.build_volume.bed_origin
            return [ConsoleLine("reply", line, now) for line in status_lines(view, bed)]
        if cmd.op == "estop":
            self.emergency_stop()
            return [ConsoleLine("reply", "emergency stop sent (bypasses the queue)", now)]
        if cmd.op in ("speed", "flow"):
            refused = self.override(cmd.op, cmd.values["percent"])
            if refused:
                return [ConsoleLine("error", refused, now)]
            return [
                ConsoleLine(
                    "reply",
                    f"ok {cmd.op} {cmd.values['percent']:g} %: from the motion not sent yet "
                    "(about a second)",
                    now,
                )
            ]
        return [
            ConsoleLine(
                "error",
                "a print is running: only M105 and M114 are answered now, and the overrides "
                "M220 / M221",
                now,
            )
        ]

    def override(self, what: str, percent: float) -> str:
        """The running job's speed or flow override (percent); the refusal, or ""."""
        with self._job_lock:
            job = self._job
        request = getattr(job, f"request_{what}", None)
        if job is None or request is None or not self.state.job_active:
            return f"no print is running: nothing to set the {what} of"
        try:
            request(percent)
        except ValueError as exc:
            return str(exc)
        asked = self._overrides_asked
        if asked is None or asked[0] is not job:
            asked = (job, {})
            self._overrides_asked = asked
        asked[1][what] = float(percent)
        return ""

    def override_step(self, what: str, step: float) -> None:
        """A key on the print screen: the override up or down by ``step`` percent (within
        10-500 %), from what was last asked of this job."""
        with self._job_lock:
            job = self._job
        asked = self._overrides_asked
        shown = self.state.job.overrides
        now = shown.speed_pct if what == "speed" else shown.flow_pct
        if asked is not None and asked[0] is job:
            now = asked[1].get(what, now)
        percent = min(max(now + step, MIN_PERCENT), MAX_PERCENT)
        refused = self.override(what, percent)
        stamp = self.app.wall_clock()
        if refused:
            self.say(ConsoleLine("error", refused, stamp))
            self.app.notify(refused, severity="warning")
        else:
            self.say(ConsoleLine("notice", f"{what} override {percent:g} % asked", stamp))
