"""The terminal UI application: screens, key bindings, the command palette.

One :class:`~cdprhost.tui.state.UiState` (``CdprApp.state``) is the only thing
the screens read; it changes only in the UI thread. Job events from worker
threads reach it through an :class:`~cdprhost.tui.control.pump.EventPump` and
the job reducer, so the screen can never disagree with the job. Progress is folded at most
``fold_interval_s`` apart (one repaint per fold: once a second keeps the UI's CPU low while
the job reports progress 10 times a second); a state change, a failure or a notice is
folded at once, and what the operator does shows at once.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

from textual.app import App, SystemCommand
from textual.binding import Binding
from textual.message import Message
from textual.reactive import var
from textual.screen import Screen

from cdprhost.job.state import Failure, JobState, Notice, StateChanged
from cdprhost.tui.control.backend import EMBEDDED, Backend
from cdprhost.tui.control.controller import Controller
from cdprhost.tui.control.pump import EventPump
from cdprhost.tui.control.store import JobHistory, RecentFiles, screenshot_dir, tui_dir
from cdprhost.tui.control.views import ConsoleLine
from cdprhost.tui.screens.calibrate import CalibrateScreen
from cdprhost.tui.screens.connection import ConnectionScreen
from cdprhost.tui.screens.console import ConsoleScreen
from cdprhost.tui.screens.diagnose import DiagnoseScreen
from cdprhost.tui.screens.dialogs import ConfirmScreen
from cdprhost.tui.screens.help import HelpScreen
from cdprhost.tui.screens.history import HistoryScreen
from cdprhost.tui.screens.jog import JogScreen
from cdprhost.tui.screens.print_screen import PrintScreen
from cdprhost.tui.state import CONSOLE_LINES, UiState, fold_job_events, shown_job_state
from cdprhost.tui.tabs import TAB_OF, TABS


class EventsReady(Message):
    """Job events are waiting in the pump."""


def job_console_lines(items: list[tuple[int, Any]], job_id: int, now: float) -> list[ConsoleLine]:
    """What a job said that belongs in the console: state changes, messages, the failure."""
    out = []
    for jid, event in items:
        if jid != job_id:
            continue
        if isinstance(event, StateChanged):
            reason = f": {event.reason}" if event.reason else ""
            out.append(ConsoleLine("notice", f"job {event.state.value}{reason}", now))
        elif isinstance(event, Notice):
            out.append(ConsoleLine("notice", event.text, now))
        elif isinstance(event, Failure):
            out.append(ConsoleLine("error", f"print stopped: {event.reason}", now))
    return out


class CdprApp(App[int]):
    TITLE = "cdprhost"
    CSS_PATH = [
        "app.tcss",
        "print.tcss",
        "connection.tcss",
        "jog.tcss",
        "calibrate.tcss",
        "diagnose.tcss",
        "console.tcss",
    ]
    MODES = {
        "connection": ConnectionScreen,
        "print": PrintScreen,
        "jog": JogScreen,
        "calibrate": CalibrateScreen,
        "diagnose": DiagnoseScreen,
        "console": ConsoleScreen,
        "history": HistoryScreen,
    }
    DEFAULT_MODE = "print"
    HORIZONTAL_BREAKPOINTS = [(0, "-narrow"), (120, "-wide")]
    BINDINGS = [
        *(
            Binding(t.key, f"app.switch_mode('{t.mode}')", t.label, tooltip=t.help, show=False)
            for t in TABS
        ),
        Binding("question_mark", "help", "Keys", tooltip="Every key of this screen"),
        Binding("ctrl+s", "screenshot", "Screenshot", show=False, tooltip="Save an SVG"),
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
        fold_interval_s: float = 1.0,
        open_file: str | None = None,
        state_folder: Path | None = None,
        clock: Callable[[], float] = time.monotonic,
        wall_clock: Callable[[], float] = time.time,
    ):
        super().__init__()
        self.backend = backend
        self.pump = EventPump(
            lambda: self.post_message(EventsReady()),
            urgent=lambda e: isinstance(e, (StateChanged, Failure, Notice)),
        )
        self.controller = Controller(self, backend)
        self.clock, self.wall_clock = clock, wall_clock
        folder = state_folder or tui_dir()
        self.recent_files = RecentFiles(folder / "recent.json")
        self.job_history = JobHistory(folder / "history.jsonl")
        self._screenshots = (folder / "screenshots") if state_folder else None
        self._port = port
        self._baud = baud or backend.profile.serial.baud
        self._connect_on_start = connect_on_start
        self._open_file = open_file
        self._intervals = (health_interval_s, status_interval_s)
        self._fold_interval = fold_interval_s
        self.last_fold = float("-inf")
        self._fold_pending = False
        self._failure_shown: int = 0
        self.problems: list[str] = []

    # -------------------------------------------------------------- life
    def on_mount(self) -> None:
        health, status = self._intervals
        if health > 0:
            self.set_interval(health, self.controller.poll_health)
        if status > 0:
            self.set_interval(status, self.controller.refresh_device)
        recent, history = self.recent_files, self.job_history
        self.controller.background(
            "stores",
            lambda: (recent.load(), history.load()),
            lambda loaded: self.controller.update(
                recent=loaded[0], history=(*self.state.history, *loaded[1])
            ),
        )
        if self._connect_on_start:
            self.controller.connect(self._port, self._baud)
        if self._open_file:
            self.controller.open_file(self._open_file)

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
        wait = self.last_fold + self._fold_interval - self.clock()
        if wait <= 0 or self.pump.urgent:
            self.drain_events()
        elif not self._fold_pending:
            self._fold_pending = True
            self.set_timer(wait, self.drain_events)

    def drain_events(self) -> None:
        """Fold every queued job event into the state now."""
        self._fold_pending = False
        self.last_fold = now = self.clock()
        items = self.pump.drain()
        if not items:
            return
        new, problems = fold_job_events(self.state, items, now)
        self.problems.extend(problems)
        lines = job_console_lines(items, new.job_id, self.wall_clock())
        if lines:
            new = replace(new, console=(*new.console, *lines)[-CONSOLE_LINES:])
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

    def action_help(self) -> None:
        screen = self.screen
        if isinstance(screen, HelpScreen):
            return
        mode = getattr(screen, "MODE", "")
        title = TAB_OF[mode].label if mode in TAB_OF else type(screen).__name__
        self.push_screen(HelpScreen(title, screen))

    def deliver_screenshot(
        self, filename: str | None = None, path: str | None = None, time_format: str | None = None
    ) -> str | None:
        """Screenshots go to the UI's own folder (created), never a Downloads folder that may
        not exist."""
        folder = self._screenshots or screenshot_dir()
        folder.mkdir(parents=True, exist_ok=True)
        return super().deliver_screenshot(filename, path or str(folder), time_format)

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
            "Cancel the print? The machine stops at the end of the queued moves, then parks "
            "as the profile says.",
            self.controller.cancel,
        )

    def action_resume_failed(self) -> None:
        self.controller.resume_failed()

    def check_print_action(self, action: str) -> bool | None:
        """Enabled state of the print actions from the job state (None: shown greyed)."""
        state = self.state
        s, pre = shown_job_state(state), state.file.preflight
        if action == "start_print":
            ready = bool(state.file.path) and pre is not None and pre.ok and state.connected
            return None if state.job_active or not ready else True
        if action == "pause_print":
            return s in (JobState.PRINTING, JobState.HEATING)
        if action == "resume_print":
            return s is JobState.PAUSED
        if action == "cancel_print":
            return True if s.active and s is not JobState.CANCELLING else None
        if action == "resume_failed":
            resume = state.file.resume
            usable = resume is not None and not resume.problem and state.connected
            return None if state.job_active or not usable else True
        return True

    # ---------------------------------------------------- command palette
    def get_system_commands(self, screen: Screen[Any]) -> Iterable[SystemCommand]:
        for t in TABS:
            yield SystemCommand(
                f"Screen: {t.label} ({t.key})", t.help, lambda m=t.mode: self.switch_mode(m)
            )
        c = self.controller
        for action, title, help_ in (
            ("start_print", "Print: start", "Start printing the open file (asks first)"),
            ("pause_print", "Print: pause", "Pause at the end of the queued moves"),
            ("resume_print", "Print: resume", "Resume a paused print (asks first)"),
            ("cancel_print", "Print: cancel", "Cancel the print (asks first)"),
            ("resume_failed", "Print: resume stopped", "Resume a stopped print (checks first)"),
        ):
            if self.check_print_action(action):
                yield SystemCommand(title, help_, getattr(self, f"action_{action}"))
        if self.state.connected:
            yield SystemCommand("Device: disconnect", "Close the link", c.disconnect)
            yield SystemCommand(
                "Device: emergency stop", "Stop now, bypassing the queue", c.emergency_stop
            )
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
        yield SystemCommand("Keys", "Every key of this screen (?)", self.action_help)
        yield from super().get_system_commands(screen)
