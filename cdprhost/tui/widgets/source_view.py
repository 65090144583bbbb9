"""A few G-code lines around one line, that line highlighted."""

from __future__ import annotations

from rich.text import Text
from textual.widget import Widget


class SourceView(Widget):
    """The title wraps (it may carry a violation's detail); the source lines are cut at the
    widget's width (one line each)."""

    DEFAULT_CSS = "SourceView { height: auto; }"

    def __init__(self, *, id: str | None = None, classes: str | None = None):
        super().__init__(id=id, classes=classes)
        self._shown: tuple[tuple[tuple[int, str], ...], int | None, str] = ((), None, "")

    def show(self, lines: list[tuple[int, str]], focus: int | None, title: str = "") -> None:
        key = (tuple(lines), focus, title)
        if key != self._shown:
            # a new line count or title changes the height: that needs a layout pass
            resized = (len(lines), title) != (len(self._shown[0]), self._shown[2])
            self._shown = key
            self.refresh(layout=resized)

    def render(self) -> Text:
        lines, focus, title = self._shown
        width = max(self.size.width, 10)
        out = Text(title + "\n", style="bold") if title else Text()
        if not lines:
            return out.append("(no G-code line)", style="dim")
        for i, (number, text) in enumerate(lines):
            mark = number == focus
            out.append(
                f"{'>' if mark else ' '}{number:>7} ", style="bold yellow" if mark else "dim"
            )
            room = width - 9
            shown = text if len(text) <= room else text[: max(room - 1, 0)] + "…"
            out.append(shown, style="reverse" if mark else "")
            if i < len(lines) - 1:
                out.append("\n")
        return out
