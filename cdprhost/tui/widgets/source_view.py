"""A few G-code lines around one line, that line highlighted."""

from __future__ import annotations

from rich.console import Group
from rich.text import Text
from textual.widgets import Static


class SourceView(Static):
    def show(self, lines: list[tuple[int, str]], focus: int | None, title: str = "") -> None:
        """``title`` wraps (it may carry a violation's detail); the source lines are cut."""
        body = Text(no_wrap=True, overflow="ellipsis")
        if not lines:
            body.append("(no G-code line)", style="dim")
        for i, (number, text) in enumerate(lines):
            mark = number == focus
            body.append(
                f"{'>' if mark else ' '}{number:>7} ", style="bold yellow" if mark else "dim"
            )
            body.append(text, style="reverse" if mark else "")
            if i < len(lines) - 1:
                body.append("\n")
        self.update(Group(Text(title, style="bold"), body) if title else body)
