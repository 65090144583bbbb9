"""The top line: profile, one tab per screen (current highlighted), job state, and a badge
when the device is simulated."""

from __future__ import annotations

from collections.abc import Sequence

from textual import events
from textual.content import Content
from textual.widgets import Static

from cdprhost.job.state import JobState
from cdprhost.tui.tabs import Tab


def nav_markup(
    title: str,
    tabs: Sequence[Tab],
    current: str,
    state: JobState,
    badge: str = "",
    short: bool = False,
) -> str:
    """Textual markup for the bar; clicking a tab switches to its screen. ``short`` uses
    the short labels of the tabs that are not current (narrow terminals)."""
    parts = [f"[b]{Content(title).markup}[/b] "] if title else []
    for t in tabs:
        style = "reverse b" if t.mode == current else "dim"
        label = t.short if short and t.mode != current else t.label
        parts.append(f"[{style} @click=app.switch_mode('{t.mode}')] {t.key.upper()} {label} [/]")
    parts.append(f" [b]{state.value}[/b]")
    if badge:
        parts.append(f" [b reverse $warning] {badge} [/]")
    return "".join(parts)


class NavBar(Static):
    def __init__(self, *, id: str | None = None):
        super().__init__(id=id)
        self._args: tuple[str, Sequence[Tab], str, JobState, str] | None = None

    def show(
        self, title: str, tabs: Sequence[Tab], current: str, state: JobState, badge: str = ""
    ) -> None:
        args = (title, tabs, current, state, badge)
        if args == self._args:
            return
        self._args = args
        self._draw()

    def _draw(self) -> None:
        if self._args is None:
            return
        title, tabs, current, state, badge = self._args
        width = self.size.width
        small_badge = badge[:3] if badge else ""
        for t, short, b in (
            (title, False, badge),
            ("", False, badge),
            ("", True, badge),
            ("", True, small_badge),
        ):
            content = Content.from_markup(nav_markup(t, tabs, current, state, b, short))
            if not width or content.cell_length <= width:
                break
        self.update(content)

    def on_resize(self, _: events.Resize) -> None:
        self._draw()
