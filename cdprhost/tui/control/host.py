"""The app as the controller sees it: what the controller may ask of the application that
holds it (the state it folds, the clocks, the workers, the dialogs). ``tui/app.py``
satisfies it; the controller never imports the app, so control/ stands below it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from cdprhost.tui.control.pump import EventPump
from cdprhost.tui.control.store import JobHistory, RecentFiles
from cdprhost.tui.state import UiState


class ControllerHost(Protocol):
    state: UiState
    pump: EventPump
    recent_files: RecentFiles
    job_history: JobHistory

    @property
    def clock(self) -> Callable[[], float]: ...

    @property
    def wall_clock(self) -> Callable[[], float]: ...

    def call_later_safe(self, fn: Callable[..., Any], *args: Any) -> None: ...

    def run_worker(self, work: Any, *args: Any, **kwargs: Any) -> Any: ...

    def notify(self, message: str, *args: Any, **kwargs: Any) -> None: ...

    def confirm(self, question: str, then: Callable[[], None]) -> None: ...

    def drain_events(self) -> None: ...

    def exit(self, *args: Any, **kwargs: Any) -> None: ...
