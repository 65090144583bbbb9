"""The console: send one command (G-code words an operator knows), read the replies, the
device's errors and what the print job said."""

from __future__ import annotations

import time

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.widgets import Input, Label, RichLog

from cdprhost.tui.control.views import ConsoleLine
from cdprhost.tui.keys import hint
from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.state import CONSOLE_LINES, UiState

KIND_STYLE = {
    "sent": "bold cyan",
    "reply": "",
    "error": "bold red",
    "device": "yellow",
    "notice": "dim",
}
KIND_MARK = {"sent": ">", "reply": " ", "error": "!", "device": "*", "notice": "#"}


def console_text(line: ConsoleLine) -> Text:
    stamp = time.strftime("%H:%M:%S", time.localtime(line.at)) if line.at else "--:--:--"
    out = Text(f"{stamp} ", style="dim")
    out.append(f"{KIND_MARK.get(line.kind, ' ')} {line.text}", style=KIND_STYLE.get(line.kind, ""))
    return out


class ConsoleScreen(AppScreen):
    MODE = "console"
    AUTO_FOCUS = "#console-input"
    BINDINGS = [
        Binding("c", "command", "Command", tooltip="Type a command (help lists them)"),
        Binding("ctrl+l", "clear", "Clear"),
        Binding("up", "recall(-1)", "Previous command", show=False),
        Binding("down", "recall(1)", "Next command", show=False),
        Binding("escape", "leave_input", "Back", show=False),
    ]

    def __init__(self) -> None:
        super().__init__(id="console-screen")
        self._written: ConsoleLine | None = None
        self._count = 0
        self._sent: list[str] = []
        self._recall = 0

    def compose_body(self) -> ComposeResult:
        yield RichLog(id="console-log", wrap=True, max_lines=CONSOLE_LINES, auto_scroll=True)
        yield Label(id="console-hint", classes="hint")
        yield Input(
            placeholder="G28, G1 X10 Z150, M104 S200, M105, M114, M112, help ... Enter sends",
            compact=True,
            id="console-input",
        )

    def on_mount(self) -> None:
        app = self.app
        leave = hint(app, self, "leave_input").split(" ", 1)[0]
        self.query_one("#console-hint", Label).update(
            f"⏎ sends · ↑↓ recall · {leave} leaves the field, "
            f"{hint(app, self, 'command')} comes back · help lists commands"
        )
        super().on_mount()

    @property
    def last_written(self) -> ConsoleLine | None:
        """The last console line written to the log (None: none yet)."""
        return self._written

    def render_state(self, state: UiState) -> None:
        lines = state.console
        log = self.query_one(RichLog)
        new: tuple[ConsoleLine, ...]
        if self._written is None:
            new = lines
        else:
            # the lines after the last one written (all of them when it was trimmed away)
            idx = next(
                (i for i in range(len(lines) - 1, -1, -1) if lines[i] is self._written), None
            )
            new = lines if idx is None else lines[idx + 1 :]
        for line in new:
            log.write(console_text(line))
        if lines:
            self._written = lines[-1]

    def on_input_submitted(self, event: Input.Submitted) -> None:
        text = event.value.strip()
        if not text:
            return
        self._sent.append(text)
        self._recall = len(self._sent)
        event.input.value = ""
        self.app.controller.console_send(text)

    def action_command(self) -> None:
        self.query_one("#console-input", Input).focus()

    def action_leave_input(self) -> None:
        self.query_one(RichLog).focus()

    def action_clear(self) -> None:
        self.query_one(RichLog).clear()

    def action_recall(self, step: int) -> None:
        field = self.query_one("#console-input", Input)
        if not self._sent or not field.has_focus:
            return
        self._recall = min(max(self._recall + step, 0), len(self._sent))
        field.value = self._sent[self._recall] if self._recall < len(self._sent) else ""
        field.cursor_position = len(field.value)
