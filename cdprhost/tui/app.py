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

import asyncio
import contextlib
import logging
import signal
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from textual import events
from textual.app import App, SystemCommand
from textual.binding import Binding
from textual.message import Message
from textual.reactive import var
from textual.screen import Screen

from cdprhost.job.state import Failure, JobState, Notice, StateChanged
from cdprhost.tui.control.backend import EMBEDDED, Backend
from cdprhost.tui.control.controller import Controller
from cdprhost.tui.control.log_route import ConsoleHandler, route_logging
from cdprhost.tui.control.pump import EventPump
from cdprhost.tui.control.store import (
    HISTORY_MAX,
    JobHistory,
    RecentFiles,
    screenshot_dir,
    tui_dir,
)
from cdprhost.tui.control.views import ConsoleLine
from cdprhost.tui.keys import action_name
from cdprhost.tui.screens.calibrate import CalibrateScreen
from cdprhost.tui.screens.connection import ConnectionScreen
from cdprhost.tui.screens.console import ConsoleScreen
from cdprhost.tui.screens.diagnose import DiagnoseScreen
from cdprhost.tui.screens.dialogs import ConfirmScreen, start_text
from cdprhost.tui.screens.help import HelpScreen
from cdprhost.tui.screens.history import HistoryScreen
from cdprhost.tui.screens.jog import JogScreen
from cdprhost.tui.screens.print_screen import PrintScreen
from cdprhost.tui.state import CONSOLE_LINES, UiState, fold_job_events, shown_job_state
from cdprhost.tui.tabs import TAB_OF, TABS, screen_key

if TYPE_CHECKING:  # pragma: no cover
    from cdprhost.tui.screens.host import ScreenHost

ESTOP_KEY = "f9"
ESTOP_ARM_S = 3.0
"""The emergency stop is a double press of its key within this many seconds: fast to do on
purpose, hard to do by accident (a dialog would cost a look and a second key anyway)."""
STOP_SIGNALS = ("SIGTERM", "SIGHUP", "SIGINT")
QUIT_LEAVING = (
    "A print is running in the printer service. Quit and leave it printing (`cdprhost tui` "
    "shows it again), cancel it (stop, park, heaters off, resume point saved) and quit when the "
    "machine is at rest, or stay (No)?"
)

log = logging.getLogger(__name__)


class EventsReady(Message):
    """Job events are waiting in the pump."""


class LogReady(Message):
    """Log records are waiting for the console."""


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
        Binding(
            ESTOP_KEY,
            "emergency_stop",
            "E-STOP",
            priority=True,  # from every screen, dialog and field
            tooltip=f"Press twice within {ESTOP_ARM_S:g} s: stop now, bypassing the queue",
        ),
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
        self.log_file = folder / "tui.log"
        self._log_lines = ConsoleHandler(lambda: self.post_message(LogReady()))
        self._unroute_logging: Callable[[], None] = lambda: None
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
        self._estop_armed: float | None = None  # when the e-stop key was first pressed
        self.problems: list[str] = []

    # -------------------------------------------------------------- life
    def on_mount(self) -> None:
        self._unroute_logging = route_logging(self._log_lines, self.log_file)
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
                recent=loaded[0], history=(*self.state.history, *loaded[1])[:HISTORY_MAX]
            ),
        )
        if self._connect_on_start:
            self.controller.connect(self._port, self._baud)
        if self._open_file:
            self.controller.open_file(self._open_file)
        if not self.is_headless:
            self._catch_stop_signals()

    @property
    def print_outlives_ui(self) -> bool:
        """The print runs in the printer service (the default backend): it goes on when this
        process ends. In-process (``--in-process``) it dies with the process."""
        return bool(getattr(self.backend, "print_outlives_ui", False))

    def _catch_stop_signals(self) -> None:
        """SIGTERM, SIGHUP, SIGINT: with the print in the service, the UI leaves and the print
        goes on (a closed terminal or a dropped ssh never stops it); in-process, they stop
        the machine like the quit key (no question asked)."""
        loop = asyncio.get_running_loop()
        for name in STOP_SIGNALS:
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.add_signal_handler(getattr(signal, name), self.on_stop_signal, name)

    def on_stop_signal(self, name: str) -> None:
        if self.print_outlives_ui:
            self.leave(name)
        else:
            self.controller.stop_and_quit(name)

    def leave(self, why: str) -> None:
        """Quit without touching the print: it goes on in the printer service (said in the
        log; a new ``cdprhost tui`` attaches to it)."""
        what = "a print started there"
        if self.state.job_active:
            what = f"the print of {self.state.job_path or 'the file'}"
        log.warning(
            "%s: the terminal UI quits; %s goes on in the printer service (`cdprhost tui` "
            "shows it again)",
            why,
            what,
        )
        self.exit(0)

    def on_unmount(self) -> None:
        """The link closes last: in-process, a job still running is stopped (and waited for)
        first; a print in the service is left to it (the UI only lets go of the device)."""
        if not self.print_outlives_ui:
            self.controller.stop_before_close()
        with contextlib.suppress(Exception):  # closing must not mask the exit
            self.backend.close()
        self._unroute_logging()

    def on_log_ready(self, _: LogReady) -> None:
        self.controller.say(*self._log_lines.drain())

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
        new, problems = fold_job_events(self.state, items, now, self.wall_clock())
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
                self.notify(
                    f"print failed: {job.reason}", severity="error", timeout=10, markup=False
                )

    # ------------------------------------------------------------ actions
    async def action_quit(self) -> None:
        if self.controller.quitting:  # asked again while the machine stops: e-stop, then exit
            self.controller.stop_and_quit()
            return
        if not self.state.job_active:
            self.exit(0)
            return
        if self.print_outlives_ui:
            self.push_screen(
                ConfirmScreen(QUIT_LEAVING, other="Cancel the print", yes="Leave it printing"),
                self._quit_chosen,
            )
            return
        self.confirm(
            "A print is running. Stop it (like a cancel: stop, park, heaters off, resume point "
            "saved) and quit when the machine is at rest?",
            self.controller.stop_and_quit,
        )

    def _quit_chosen(self, choice: bool | str | None) -> None:
        if choice is True:
            self.leave("quit")
        elif choice == "other":  # cancelled like a cancel, then the exit once at rest
            self.controller.stop_and_quit("quit")
        # else: stay

    def action_emergency_stop(self) -> None:
        """First press arms, a second within ``ESTOP_ARM_S`` stops."""
        now = self.clock()
        if not self.state.connected and not self.state.job_active:
            self.notify("not connected: there is no device to stop", severity="warning")
            return
        if self._estop_armed is None or now - self._estop_armed > ESTOP_ARM_S:
            self._estop_armed = now
            key = self.get_key_display(self._estop_binding())
            self.notify(
                f"press {key} again within {ESTOP_ARM_S:g} s to stop the machine NOW "
                "(bypasses the queue; heaters off)",
                title="emergency stop armed",
                severity="error",
                timeout=ESTOP_ARM_S,
            )
            return
        self._estop_armed = None
        self.controller.emergency_stop()

    def _estop_binding(self) -> Binding:
        return next(b for b in self.BINDINGS if isinstance(b, Binding) and b.key == ESTOP_KEY)

    def confirm(self, question: str, then: Callable[[], None]) -> None:
        self.push_screen(ConfirmScreen(question), lambda yes: then() if yes is True else None)

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
        """Asks first, naming a fault the device reports (starting clears it) and offering a
        resume point saved for this file."""
        why = self.why_not_print("start_print")
        if why:
            self.notify(f"cannot start: {why}", severity="warning")
            return
        state = self.state
        path, resume = state.file.path, state.file.resume
        usable = resume is not None and not resume.problem
        fault = state.device.fault if state.device is not None else ""
        c = self.controller

        def chosen(choice: bool | str | None) -> None:
            if choice == "other":  # the link checked, the part on the bed confirmed
                c.resume_failed()
            elif choice is True:  # a fault shown here is cleared at the start; one found
                c.start(clear_fault=bool(fault))  # later (not shown) is refused

        other = "Resume there" if usable else ""
        self.push_screen(ConfirmScreen(start_text(path, fault, resume), other, "Start"), chosen)

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

    def why_not_print(self, action: str) -> str:
        """Why a print action cannot act now ("" when it can): what the key says when pressed,
        and what the help shows."""
        state = self.state
        s, f = shown_job_state(state), state.file
        link = f"not connected: connect on {screen_key('connection')}"
        running = "a print is running"
        if action in ("start_print", "resume_failed"):
            if state.job_active:
                return running
            if not f.path:
                return "no file open: open one first"
            if f.checking:
                return "the file is still being checked"
            if action == "resume_failed":
                if f.resume is None:
                    return "no resume point is saved for this file"
                if f.resume.problem:
                    return f.resume.problem
            elif f.error or f.preflight is None:
                return f"the file could not be checked: {f.error or 'no result'}"
            elif not f.preflight.ok:
                return "the preflight found violations (the list shows them)"
            if not state.connected:
                return link
            dev = state.device
            if dev is not None and dev.fault and not dev.fault_clearable:
                return f"{dev.fault}: it cannot be cleared from here (check, power-cycle)"
            return f"busy: {state.busy}" if state.busy else ""
        if not s.active:
            return "no print is running"
        if action == "pause_print":
            if s is JobState.PAUSED:
                return "already paused"
            return "" if s in (JobState.PRINTING, JobState.HEATING) else f"the print is {s.value}"
        if action == "resume_print":
            return "" if s is JobState.PAUSED else "the print is not paused"
        if action == "cancel_print":
            return "already cancelling" if s is JobState.CANCELLING else ""
        return ""

    def check_print_action(self, action: str) -> bool | None:
        """Enabled state of the print actions: True, None (greyed: the key says why), False
        (hidden: no link and no job, so nothing to start or stop)."""
        if not self.why_not_print(action):
            return True
        if not self.state.connected and not self.state.job_active:
            return False
        return None

    def why_not(self, action: str) -> str:
        if action == "emergency_stop" and not (self.state.connected or self.state.job_active):
            return "not connected: there is no device to stop"
        return ""

    def on_key(self, event: events.Key) -> None:
        """A key bound to an action that cannot act now says why, never nothing."""
        reasons = []
        for namespace, bindings in self.screen._modal_binding_chain:
            for b in bindings.key_to_bindings.get(event.key, ()):
                name = action_name(b)
                if namespace.check_action(name, ()):
                    return  # it acted (or another binding of the key did)
                why = getattr(namespace, "why_not", None)
                reason = why(name) if why is not None else ""
                if reason:
                    reasons.append(f"{self.get_key_display(b)} {b.description}: {reason}")
        if reasons:
            self.notify(reasons[0], title="not now", severity="warning", timeout=4)

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


if TYPE_CHECKING:  # pragma: no cover - the type checker holds the app to what screens ask

    def _screen_host(app: CdprApp) -> ScreenHost:
        return app
