"""The terminal UI application: screens, key bindings, the command palette.

One :class:`~cdprhost.tui.state.UiState` (``CdprApp.state``) is the only thing
the screens read; it changes only in the UI thread. Job events from worker
threads reach it through an :class:`~cdprhost.tui.control.pump.EventPump` and
the job reducer, so the screen can never disagree with the job.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from typing import Any

from textual.app import App, SystemCommand
from textual.binding import Binding
from textual.message import Message
from textual.reactive import var
from textual.screen import Screen

from cdprhost.job.state import JobState
from cdprhost.tui.control.backend import EMBEDDED, Backend
from cdprhost.tui.control.controller import Controller
from cdprhost.tui.control.pump import EventPump
from cdprhost.tui.screens.calibrate import CalibrateScreen
from cdprhost.tui.screens.connection import ConnectionScreen
from cdprhost.tui.screens.diagnose import DiagnoseScreen
from cdprhost.tui.screens.dialogs import ConfirmScreen
from cdprhost.tui.screens.jog import JogScreen
from cdprhost.tui.screens.print_screen import PrintScreen
from cdprhost.tui.state import UiState, fold_job_events

SCREENS_ORDER = (
    ("connection", "f1", "Connect", "Connection: port, baud, device identity, link health"),
    ("print", "f2", "Print", "Print: open a file, preflight, start/pause/resume/cancel, progress"),
    (
        "jog",
        "f3",
        "Jog",
        "Jog: move by steps with feasibility shown first, home, motors off, heaters",
    ),
    ("calibrate", "f4", "Calibrate", "Calibrate: planned poses, takes, identification results"),
    ("diagnose", "f5", "Diagnose", "Diagnose: verdict, where, held-out gap before/after"),
)


class EventsReady(Message):
    """Job events are waiting in the pump."""


class CdprApp(App[int]):
    TITLE = "cdprhost"
    CSS_PATH = [
        "app.tcss",
        "print.tcss",
        "connection.tcss",
        "jog.tcss",
        "calibrate.tcss",
        "diagnose.tcss",
    ]
    MODES = {
        "connection": ConnectionScreen,
        "print": PrintScreen,
        "jog": JogScreen,
        "calibrate": CalibrateScreen,
        "diagnose": DiagnoseScreen,
    }
    DEFAULT_MODE = "print"
    BINDINGS = [
        *(
            Binding(key, f"app.switch_mode('{mode}')", label, tooltip=help_, show=False)
            for mode, key, label, help_ in SCREENS_ORDER
        ),
        Binding("ctrl+q", "quit", "Quit", priority=True),
    ]

    state: var[UiState] = var(UiState, init=False)

    def __init__(
        self,
        backend: Backend,
        *,
        port: str = EMBEDDED,
        baud: int | None = None,
        connect_on_start: bool = True,
        health_interval_s: float = 0.5,
        status_interval_s: float = 1.0,
    ):
        super().__init__()
        self.backend = backend
        self.pump = EventPump(lambda: self.post_message(EventsReady()))
        self.controller = Controller(self, backend)
        self._port = port
        self._baud = baud or backend.profile.serial.baud
        self._connect_on_start = connect_on_start
        self._intervals = (health_interval_s, status_interval_s)
        self._failure_shown: int = 0
        self.problems: list[str] = []

    # -------------------------------------------------------------- life
    def on_mount(self) -> None:
        health, status = self._intervals
        if health > 0:
            self.set_interval(health, self.controller.poll_health)
        if status > 0:
            self.set_interval(status, self.controller.refresh_device)
        if self._connect_on_start:
            self.controller.connect(self._port, self._baud)

    def on_unmount(self) -> None:
        self.controller.cancel()
        with contextlib.suppress(Exception):  # closing must not mask the exit
            self.backend.close()

    def call_later_safe(self, fn: Callable[..., Any], *args: Any) -> None:
        """From a worker thread: run ``fn`` in the UI thread (dropped once the app has closed)."""
        with contextlib.suppress(RuntimeError):
            self.call_from_thread(fn, *args)

    # ------------------------------------------------------------ events
    def on_events_ready(self, _: EventsReady) -> None:
        new, problems = fold_job_events(self.state, self.pump.drain())
        self.problems.extend(problems)
        if new is not self.state:
            self.state = new
        self._after_job_change()

    def _after_job_change(self) -> None:
        job = self.state.job
        if job.state is JobState.FAILED and self._failure_shown != self.state.job_id:
            self._failure_shown = self.state.job_id
            if isinstance(self.screen, PrintScreen):
                self.screen.show_failure()
            else:
                self.notify(f"print failed: {job.reason}", severity="error", timeout=10)

    def job_finished(self, job_id: int, result: Any, error: BaseException | None) -> None:
        """The runner returned (or raised); its events may still be in the pump."""
        self.on_events_ready(EventsReady())
        if job_id != self.state.job_id:
            return
        if error is not None:
            self.notify(
                str(error) or type(error).__name__, title="print", severity="error", timeout=10
            )
        elif self.state.job.state is JobState.DONE:
            self.notify("print finished", title="print")

    # ------------------------------------------------------------ actions
    async def action_quit(self) -> None:
        if not self.state.job_active:
            self.exit(0)
            return

        def cancel_and_quit() -> None:
            self.controller.cancel()
            self.exit(0)

        self.confirm("A print is running. Cancel it and quit?", cancel_and_quit)

    def confirm(self, question: str, then: Callable[[], None]) -> None:
        self.push_screen(ConfirmScreen(question), lambda yes: then() if yes else None)

    def action_start_print(self) -> None:
        path = self.state.file.path
        if not path:
            self.notify("open a G-code file first", severity="warning")
            return
        self.confirm(f"Start printing {path}?", self.controller.start)

    def action_pause_print(self) -> None:
        self.controller.pause()

    def action_resume_print(self) -> None:
        self.confirm("Resume the print?", self.controller.resume)

    def action_cancel_print(self) -> None:
        self.confirm(
            "Cancel the print? The machine stops at the end of the queued moves.",
            self.controller.cancel,
        )

    def check_print_action(self, action: str) -> bool | None:
        """Enabled state of the print actions from the job state (None: shown greyed)."""
        s, pre = self.state.job.state, self.state.file.preflight
        if action == "start_print":
            ready = (
                bool(self.state.file.path) and pre is not None and pre.ok and self.state.connected
            )
            return None if self.state.job_active or not ready else True
        if action == "pause_print":
            return s in (JobState.PRINTING, JobState.HEATING)
        if action == "resume_print":
            return s is JobState.PAUSED
        if action == "cancel_print":
            return True if s.active and s is not JobState.CANCELLING else None
        return True

    # ---------------------------------------------------- command palette
    def get_system_commands(self, screen: Screen) -> Iterable[SystemCommand]:
        for mode, key, label, help_ in SCREENS_ORDER:
            yield SystemCommand(
                f"Screen: {label} ({key})", help_, lambda m=mode: self.switch_mode(m)
            )
        c = self.controller
        for action, title, help_ in (
            ("start_print", "Print: start", "Start printing the open file (asks first)"),
            ("pause_print", "Print: pause", "Pause at the end of the queued moves"),
            ("resume_print", "Print: resume", "Resume a paused print (asks first)"),
            ("cancel_print", "Print: cancel", "Cancel the print (asks first)"),
        ):
            if self.check_print_action(action):
                yield SystemCommand(title, help_, getattr(self, f"action_{action}"))
        if self.state.connected:
            yield SystemCommand("Device: disconnect", "Close the link", c.disconnect)
            if not self.state.job_active:
                yield SystemCommand("Device: home", "Drive the modules to their endstops", c.home)
                yield SystemCommand(
                    "Device: motors off", "Disable the stepper drivers", c.motors_off
                )
        else:
            yield SystemCommand(
                "Device: connect",
                f"Connect to {self._port}",
                lambda: c.connect(self._port, self._baud),
            )
        yield from super().get_system_commands(screen)
