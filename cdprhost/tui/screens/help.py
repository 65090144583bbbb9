"""The ``?`` screen: every key of the screen below and of the whole app, read from the
bindings (the same labels as the footer), greyed when not possible right now."""

from __future__ import annotations

from rich.table import Table
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical, VerticalScroll
from textual.dom import DOMNode
from textual.screen import ModalScreen
from textual.widgets import Label, Static

from cdprhost.tui.keys import KeyRow, key_rows

ENTER = KeyRow("⏎", "Act on the focused item (connect, open, jump to a line, send)", "", True)


def keys_table(title: str, rows: list[KeyRow] | tuple[KeyRow, ...]) -> Table:
    table = Table(title=title, title_justify="left", title_style="bold", box=None, expand=True)
    table.add_column("key", style="bold", no_wrap=True, min_width=8)
    table.add_column("does", ratio=1)
    for row in rows:
        does = Text(row.description)
        if row.tooltip and row.tooltip != row.description:
            does.append(f"  {row.tooltip}", style="dim")
        if not row.enabled:
            does.append(f"  (not now: {row.why or 'not possible in this state'})", style="italic")
        table.add_row(Text(row.keys, style="bold" if row.enabled else "dim"), does)
    return table


class HelpScreen(ModalScreen[None]):
    BINDINGS = [Binding("escape,question_mark,q", "close", "Close")]

    def __init__(self, screen_title: str, screen_node: DOMNode):
        super().__init__(classes="dialog-screen")
        self.screen_title, self.screen_node = screen_title, screen_node

    def compose(self) -> ComposeResult:
        app = self.app
        with Vertical(classes="dialog help"):
            yield Label(
                f"Keys: {self.screen_title} (esc closes; same labels as the key bar)",
                classes="section-title",
            )
            palette = Binding(app.COMMAND_PALETTE_BINDING, "command_palette", "Command palette")
            everywhere = [
                *key_rows(app, app),
                KeyRow(
                    app.get_key_display(palette), "Command palette", "search every command", True
                ),
            ]
            moving = [*key_rows(app, self.screen_node, ours=False), ENTER]
            with VerticalScroll(id="help-body"):
                yield Static(keys_table("This screen", key_rows(app, self.screen_node)))
                yield Static(keys_table("Everywhere", everywhere))
                yield Static(keys_table("Moving around", moving))

    def action_close(self) -> None:
        self.dismiss(None)
