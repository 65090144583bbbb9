"""The job history: every finished print (newest first); Enter reopens its file."""

from __future__ import annotations

import time
from pathlib import Path

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.widgets import DataTable, Label

from cdprhost.tui.control.views import JobRecord
from cdprhost.tui.keys import hint
from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.state import UiState, hms

STATUS_STYLE = {"done": "bold green", "cancelled": "yellow", "failed": "bold red"}


def history_row(r: JobRecord) -> tuple[str | Text, ...]:
    when = time.strftime("%Y-%m-%d %H:%M", time.localtime(r.started)) if r.started else "?"
    layers = f"{r.layers_done}/{r.layers}" if r.layers else "-"
    if r.resumed_from_layer:
        layers += f" (from {r.resumed_from_layer})"
    return (
        when,
        Path(r.file).name,
        Text(r.status, style=STATUS_STYLE.get(r.status, "")),
        layers,
        hms(r.duration_s),
        " · ".join(
            x for x in (r.reason, f"resume point {r.resume_at}" if r.resume_at else "") if x
        ),
    )


class HistoryScreen(AppScreen):
    MODE = "history"
    AUTO_FOCUS = "#history-table"
    BINDINGS = [
        Binding("o", "reopen", "Open its file", tooltip="On the print screen"),
    ]

    def __init__(self) -> None:
        super().__init__(id="history-screen")
        self._shown: tuple[JobRecord, ...] | None = None

    def compose_body(self) -> ComposeResult:
        yield DataTable(id="history-table", cursor_type="row", zebra_stripes=True)
        yield Label(id="history-hint", classes="hint")

    def on_mount(self) -> None:
        table = self.query_one(DataTable)
        for name, width in (
            ("started", 16),
            ("file", 22),
            ("result", 9),
            ("layers", 12),
            ("time", 8),
            ("note", 60),
        ):
            table.add_column(name, width=width)
        self.query_one("#history-hint", Label).update(
            f"Enter or {hint(self.app, self, 'reopen')}: the selected print's file, on the "
            "print screen"
        )
        super().on_mount()

    def render_state(self, state: UiState) -> None:
        if state.history is self._shown:
            return
        self._shown = state.history
        table = self.query_one(DataTable)
        table.clear()
        for i, r in enumerate(state.history):
            table.add_row(*history_row(r), key=str(i))

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action == "reopen":
            return True if self.app.state.history and not self.app.state.job_active else None
        return True

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        self.action_reopen()

    def action_reopen(self) -> None:
        history = self.app.state.history
        row = self.query_one(DataTable).cursor_row
        if self.app.state.job_active or not 0 <= row < len(history):
            return
        self.app.controller.open_file(history[row].file)
        self.app.switch_mode("print")
