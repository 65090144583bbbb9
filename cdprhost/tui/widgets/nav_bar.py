"""The top line: profile, one tab per screen (current highlighted), job state."""

from __future__ import annotations

from collections.abc import Sequence

from textual import events
from textual.content import Content
from textual.widgets import Static

from cdprhost.job.state import JobState

Tab = tuple[str, str, str]  # (mode, key, label)


def nav_markup(title: str, tabs: Sequence[Tab], current: str, state: JobState) -> str:
    """Textual markup for the bar; clicking a tab switches to its screen."""
    parts = [f"[b]{Content(title).markup}[/b] "] if title else []
    for mode, key, label in tabs:
        style = "reverse b" if mode == current else "dim"
        parts.append(f"[{style} @click=app.switch_mode('{mode}')] {key.upper()} {label} [/]")
    parts.append(f" [b]{state.value}[/b]")
    return "".join(parts)


class NavBar(Static):
    def __init__(self, *, id: str | None = None):
        super().__init__(id=id)
        self._args: tuple[str, Sequence[Tab], str, JobState] | None = None

    def show(self, title: str, tabs: Sequence[Tab], current: str, state: JobState) -> None:
        self._args = (title, tabs, current, state)
        content = Content.from_markup(nav_markup(title, tabs, current, state))
        if self.size.width and content.cell_length > self.size.width:  # narrow: drop the title
            content = Content.from_markup(nav_markup("", tabs, current, state))
        self.update(content)

    def on_resize(self, _: events.Resize) -> None:
        if self._args is not None:
            self.show(*self._args)
