"""What every screen shares: the tab bar on top, the key bar below, state watching."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.screen import Screen
from textual.widgets import Footer

from cdprhost.tui.state import UiState
from cdprhost.tui.widgets.nav_bar import NavBar

TABS = (
    ("connection", "f1", "Link"),
    ("print", "f2", "Print"),
    ("jog", "f3", "Jog"),
    ("calibrate", "f4", "Calibrate"),
    ("diagnose", "f5", "Diagnose"),
)


class AppScreen(Screen):
    """Subclasses set ``MODE``, yield their body from ``compose_body`` and draw in ``render_state``."""

    MODE = ""

    def compose(self) -> ComposeResult:
        yield NavBar(id="nav")
        yield from self.compose_body()
        yield Footer()

    def compose_body(self) -> ComposeResult:
        yield from ()

    def on_mount(self) -> None:
        self.watch(self.app, "state", self._state_changed)

    def on_screen_resume(self) -> None:
        self._state_changed(self.app.state)

    def _state_changed(self, state: UiState) -> None:
        self.query_one(NavBar).show(self.app.backend.profile_name, TABS, self.MODE, state.job.state)
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

    def render_state(self, state: UiState) -> None:
        """Draw ``state``; called in the UI thread on every change."""
