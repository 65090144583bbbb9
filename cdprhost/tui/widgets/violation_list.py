"""Preflight violations, one row each; selecting a row asks to show its line."""

from __future__ import annotations

from textual.message import Message
from textual.widgets import DataTable

from cdprhost.tui.control.views import ViolationRow


class ViolationList(DataTable[str]):
    class Jump(Message):
        """The user wants to see G-code line ``line``."""

        def __init__(self, line: int):
            super().__init__()
            self.line = line

    def __init__(self, *, id: str | None = None, classes: str | None = None):
        super().__init__(id=id, classes=classes, cursor_type="row", zebra_stripes=True)
        self._lines: list[int] = []
        self.shown: tuple[ViolationRow, ...] | None = None

    def on_mount(self) -> None:
        self.add_column("line", key="line", width=7)
        self.add_column("rule", key="rule", width=15)
        self.add_column("detail", key="detail", width=90)

    def show(self, violations: tuple[ViolationRow, ...]) -> None:
        self.shown = violations
        self.set_class(not violations, "-empty")
        self.clear()
        self._lines = [v.line for v in violations]
        for i, v in enumerate(violations):
            self.add_row(str(v.line), v.rule, v.detail, key=str(i))

    def on_data_table_row_selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        if 0 <= event.cursor_row < len(self._lines):
            self.post_message(self.Jump(self._lines[event.cursor_row]))
