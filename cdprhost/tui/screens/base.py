"""What every screen shares: the tab bar on top, the key bar below, state watching, and a
once-a-second tick for what ages (temperatures, clocks)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.screen import Screen

from cdprhost.tui.state import UiState, shown_job_state
from cdprhost.tui.tabs import TABS, screen_key
from cdprhost.tui.widgets.key_bar import KeyBar
from cdprhost.tui.widgets.nav_bar import NavBar

if TYPE_CHECKING:  # pragma: no cover
    from cdprhost.tui.screens.host import ScreenHost

    class HostApp(App[int], ScreenHost):
        """A Textual app that is a screen host (``tui/app.py``'s ``CdprApp``)."""


class AppScreen(Screen[None]):
    """Subclasses set ``MODE``, yield their body from ``compose_body``, draw in
    ``render_state`` and (optionally) redraw what ages in ``render_tick``."""

    MODE = ""
    TICK_S = 1.0

    if TYPE_CHECKING:  # pragma: no cover - the app these screens run in
        app: HostApp

    def compose(self) -> ComposeResult:
        yield NavBar(id="nav")
        yield from self.compose_body()
        yield KeyBar(compact=True)

    def compose_body(self) -> ComposeResult:
        yield from ()

    def on_mount(self) -> None:
        self.watch(self.app, "state", self._state_changed, init=False)
        self.set_interval(self.TICK_S, self._tick)
        self._state_changed(self.app.state)

    def on_screen_resume(self) -> None:
        self._state_changed(self.app.state)

    def _tick(self) -> None:
        app = self.app
        if not self.is_current or app.clock() - app.last_fold < self.TICK_S:
            return  # events were folded (and drawn) within the last second
        self.render_tick(app.state)

    def _state_changed(self, state: UiState) -> None:
        if not self.is_current:
            return  # drawn again when it comes back (on_screen_resume)
        c = state.connection
        self.query_one(NavBar).show(
            self.app.backend.profile_name,
            TABS,
            self.MODE,
            shown_job_state(state),
            "SIMULATOR" if c.simulated and c.status == "connected" else "",
        )
        self.render_state(state)
        signature = self._bindings_signature()
        if signature != getattr(self, "_signature", None):  # rebuilding the key bar is not free
            self._signature = signature
            self.refresh_bindings()

    def _bindings_signature(self) -> tuple[bool | None, ...]:
        """Which of this screen's actions are enabled, greyed or hidden now."""
        names = dict.fromkeys(
            b.action.split("(", 1)[0] for b in self.BINDINGS if isinstance(b, Binding)
        )
        return tuple(self.check_action(name, ()) for name in names)

    def why_not(self, action: str) -> str:
        """Why ``action`` cannot act now (said when its key is pressed, shown by the help);
        screens name their own reasons, this is what they share."""
        state = self.app.state
        if state.job_active:
            return "a print is running"
        if not state.connected:
            return f"not connected: connect on {screen_key('connection')}"
        if state.busy:
            return f"busy: {state.busy}"
        return "not possible in this state"

    def render_state(self, state: UiState) -> None:
        """Draw ``state``; called in the UI thread on every change while this screen shows."""

    def render_tick(self, state: UiState) -> None:
        """Redraw what ages with time (called once a second while this screen shows)."""
