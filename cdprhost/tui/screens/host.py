"""The app as the screens see it: what a screen may ask of the application it runs in (the
state it draws, the backend, the controller its keys drive, the clocks, the print actions
and the dialogs). ``tui/app.py`` satisfies it; no screen imports the app, so screens/ stands
below it (the app imports every screen to hold them)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from cdprhost.tui.control.backend import Backend
from cdprhost.tui.control.controller import Controller
from cdprhost.tui.state import UiState


class ScreenHost(Protocol):
    state: UiState
    backend: Backend
    controller: Controller
    last_fold: float  # when job events were last folded into the state (``clock`` time)
    _port: str  # the port the app was started on, and its baud rate
    _baud: int

    @property
    def clock(self) -> Callable[[], float]: ...

    @property
    def wall_clock(self) -> Callable[[], float]: ...

    def call_later_safe(self, fn: Callable[..., Any], *args: Any) -> None: ...

    def confirm(self, question: str, then: Callable[[], None]) -> None: ...

    def why_not_print(self, action: str) -> str: ...

    def check_print_action(self, action: str) -> bool | None: ...

    def action_start_print(self) -> None: ...

    def action_pause_print(self) -> None: ...

    def action_resume_print(self) -> None: ...

    def action_cancel_print(self) -> None: ...

    def action_resume_failed(self) -> None: ...
