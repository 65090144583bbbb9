"""The print server inside the terminal UI (``cdprhost tui --listen``): the server's
:class:`~cdprhost.server.printer.Printer` made of the TUI's own controller.

An upload is added to the recent files (so it is in the file picker) and said in the console.
An upload with ``print=true`` starts only when the TUI is connected and no job runs and the file
passes preflight; it then becomes the TUI's print (the open file, started by the controller as
the Start key does), shown, paused and cancelled there like any other, and the notification and
console say who started it. Everything that reads or changes the UI state runs in the UI thread
(``call_from_thread``); the preflight runs in the server's worker thread.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from cdprhost.errors import CdprError
from cdprhost.job.before_start import before_start
from cdprhost.job.state import JobState, Temperatures
from cdprhost.link import LinkError
from cdprhost.server.printer import PrinterStatus, Refused, busy_reason, preflight_refusal
from cdprhost.tui.control.views import ConsoleLine, PreflightView
from cdprhost.tui.state import FileView, UiState


class TuiPrinter:
    def __init__(self, app: Any):
        self.app = app
        self._checked: dict[str, PreflightView] = {}
        self._who: tuple[int, str] = (0, "")  # (job id, who started it)
        self._lock = threading.Lock()

    # ------------------------------------------------------------ helpers
    def _in_ui(self, fn: Callable[..., Any], *args: Any) -> Any:
        try:
            return self.app.call_from_thread(fn, *args)
        except RuntimeError:  # the app is not running (closing): refuse, change nothing
            raise Refused("the terminal UI is closing; nothing done") from None

    def _say(self, text: str, title: str = "upload API") -> None:  # UI thread
        # the text holds what a client sent (its User-Agent, file names): shown as it is,
        # never read as markup (``[/]`` in a User-Agent would stop the TUI)
        self.app.notify(text, title=title, markup=False)
        self.app.controller.say(ConsoleLine("notice", f"{title}: {text}", self.app.wall_clock()))

    def announce(self, text: str, wait_s: float = 30.0) -> None:
        """Say ``text`` in the TUI once it runs (from a helper thread, bounded wait)."""

        def later() -> None:
            for _ in range(int(wait_s / 0.1)):
                if self.app.is_running:
                    try:
                        self.app.call_from_thread(self._say, text)
                    except RuntimeError:
                        return
                    return
                time.sleep(0.1)

        threading.Thread(target=later, name="upload-api-announce", daemon=True).start()

    # -------------------------------------------------------------- status
    def _busy(self, state: Any) -> str:
        """Why the machine is not idle now ("" when it is): a job, or a device operation
        (jog, home, heaters) the operator started."""
        if state.job_active:  # a job started here is active (preflight) at once
            return busy_reason(self.status())
        if state.busy:
            return f"the machine is busy at the terminal UI ({state.busy}); nothing started"
        return ""

    def status(self) -> PrinterStatus:
        state = self.app.state  # one immutable value: safe to read from any thread
        job_id, who = self._who
        if not job_id or job_id != state.job_id:
            who = "the terminal UI" if state.job_path else ""
        job = state.job
        return PrinterStatus(
            connected=state.connected,
            file=Path(state.job_path) if state.job_path else None,
            started_by=who,
            job=job,
            started_at=state.job_started or None,
        )

    # --------------------------------------------------------------- start
    def check_start(self, path: Path) -> None:
        state = self.app.state
        if not state.connected:
            raise Refused("the terminal UI is not connected to a device; nothing started")
        busy = self._busy(state)
        if busy:
            raise Refused(busy)
        view = self.app.backend.preflight(str(path))
        if not view.ok:
            v = view.violations[0]
            raise Refused(preflight_refusal(len(view.violations), v.line, v.rule, v.detail))
        self._refuse_if_faulted(path)
        with self._lock:
            self._checked[path.name] = view

    def _refuse_if_faulted(self, path: Path) -> None:
        """A device stopped by a fault is the operator's to clear, at the TUI: never remotely."""
        try:
            link = self.app.backend.link
            fault = before_start(link, path).fault
        except (CdprError, LinkError, OSError) as exc:
            raise Refused(f"the device does not answer: {exc}; nothing started") from None
        if fault is not None:
            raise Refused(f"{fault}: the operator decides at the terminal UI; nothing started")

    def start(self, path: Path, who: str) -> None:
        with self._lock:
            view = self._checked.pop(path.name, None)
        if view is None:
            raise Refused(f"{path.name} was not checked before the start; nothing started")
        reason = self._in_ui(self._start_in_ui, path, who, replace(view, path=str(path)))
        if reason:
            raise Refused(reason)

    def _start_in_ui(self, path: Path, who: str, view: PreflightView) -> str:
        state = self.app.state
        busy = self._busy(state)
        if busy:
            return busy
        if not state.connected:
            return "the terminal UI is not connected to a device; nothing started"
        controller = self.app.controller
        controller.update(file=FileView(path=str(path), preflight=view))
        controller.start()
        if self.app.state.job_id == state.job_id:  # the controller did not start it
            return "the terminal UI did not start the job; nothing started"
        self._who = (self.app.state.job_id, who)
        self._say(f"print of {path.name} started by {who}")
        return ""

    # ------------------------------------------------------------ controls
    def pause(self, action: str) -> None:
        reason = self._in_ui(self._pause_in_ui, action)
        if reason:
            raise Refused(reason)

    def _pause_in_ui(self, action: str) -> str:
        s = self.app.state.job.state
        if action == "toggle":
            action = "resume" if s is JobState.PAUSED else "pause"
        if action == "pause" and s in (JobState.PRINTING, JobState.HEATING):
            self.app.controller.pause()
            self._say("pause asked")
            return ""
        if action == "resume" and s is JobState.PAUSED:
            self.app.controller.resume()
            self._say("resume asked")
            return ""
        return f"cannot {action} while {s.value}"

    def cancel(self) -> None:
        reason = self._in_ui(self._cancel_in_ui)
        if reason:
            raise Refused(reason)

    def _cancel_in_ui(self) -> str:
        state = self.app.state
        s = state.job.state
        if s is JobState.PREFLIGHT:
            return "the print is starting (preflight): cancel again in a moment"
        if not s.active:
            return f"no print is running ({s.value}): nothing to cancel"
        self.app.controller.cancel()
        self._say("cancel asked")
        return ""

    def temperatures(self) -> Temperatures | None:
        """The TUI's newest reading: the job's, else the one it polls while no job runs."""
        state: UiState = self.app.state
        if state.job.temperatures is not None and (state.job_active or not state.device):
            return state.job.temperatures
        device = state.device
        if device is None or device.hotend is None or device.bed is None:
            return state.job.temperatures
        return Temperatures(device.hotend, device.bed, device.hotend_target, device.bed_target)

    def uploaded(self, path: Path) -> None:
        recent = self.app.recent_files.add(str(path))

        def show() -> None:
            self.app.controller.update(recent=recent)
            self._say(f"stored {path.name} (in the file picker's recent files)")

        self._in_ui(show)
