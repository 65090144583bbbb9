"""A few G-code lines around one line, that line highlighted."""

from __future__ import annotations

from rich.text import Text
from textual.widget import Widget


class SourceView(Widget):
    """The title wraps (it may carry a violation's detail); each source line takes one row:
    a line too wide loses its comment first, then is cut (``fit_line``)."""

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
        digits = max(3, *(len(str(number)) for number, _ in lines))
        room = width - digits - 2
        for i, (number, text) in enumerate(lines):
            mark = number == focus
            out.append(
                f"{'>' if mark else ' '}{number:>{digits}} ",
                style="bold yellow" if mark else "dim",
            )
            out.append(fit_line(text, room), style="reverse" if mark else "")
            if i < len(lines) - 1:
                out.append("\n")
        return out


def fit_line(text: str, room: int) -> str:
    """A G-code line in ``room`` columns: whole if it fits, else without its trailing
    comment, else cut with an ellipsis (a comment-only line is cut)."""
    if len(text) <= room:
        return text
    code = text.split(";", 1)[0].rstrip()
    if code and len(code) <= room:
        return code + " ;…" if len(code) + 3 <= room else code
    return text[: max(room - 1, 0)] + "…"
