"""The connection screen: pick a port and baud, connect, see the device and the link."""

from __future__ import annotations

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import DataTable, Input, Label, OptionList
from textual.widgets.option_list import Option

from cdprhost.tui.control.views import PortChoice
from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.state import UiState


def health_text(state: UiState) -> Text:
    h = state.job.link if state.job_active else state.connection.health
    out = Text("link health  ", style="bold")
    if h is None:
        return out.append("--", style="dim")
    bad = h.bad_frames or h.retransmits
    out.append(
        f"retx {h.retransmits}  bad frames {h.bad_frames}  naks {h.naks}",
        style="yellow" if bad else "green",
    )
    return out


class ConnectionScreen(AppScreen):
    MODE = "connection"
    BINDINGS = [
        Binding("c", "connect", "Connect"),
        Binding("d", "disconnect", "Disconnect"),
        Binding("r", "rescan", "Rescan ports"),
    ]

    def __init__(self) -> None:
        super().__init__(id="connection-screen")
        self.choices: list[PortChoice] = []

    def compose_body(self) -> ComposeResult:
        with Horizontal(id="conn-top"):
            with Vertical(id="conn-ports"):
                yield Label("Ports (Enter connects)", classes="section-title")
                yield OptionList(id="port-list", compact=True)
            with Vertical(id="conn-settings"):
                yield Label("Baud", classes="section-title")
                yield Input(str(self.app._baud), type="integer", compact=True, id="baud-input")
                yield Label(id="conn-status")
                yield Label(id="conn-health")
        yield Label("Device", classes="section-title")
        yield DataTable(id="identity", show_header=False, cursor_type="none")

    def on_mount(self) -> None:
        table = self.query_one("#identity", DataTable)
        table.add_column("key", width=22)
        table.add_column("value", width=60)
        super().on_mount()
        self.action_rescan()

    def render_state(self, state: UiState) -> None:
        c = state.connection
        style = {"connected": "bold green", "connecting": "cyan", "error": "bold red"}.get(
            c.status, "dim"
        )
        status = Text.assemble(("status  ", "bold"), (c.status, style))
        if c.port:
            status.append(f"  {c.port} @ {c.baud}")
        if c.error:
            status.append(f"\n{c.error}", style="red")
        self.query_one("#conn-status", Label).update(status)
        self.query_one("#conn-health", Label).update(health_text(state))
        table = self.query_one("#identity", DataTable)
        if getattr(table, "_shown", None) != c.identity:
            table.clear()
            for key, value in c.identity:
                table.add_row(key, value)
            table._shown = c.identity

    @work(thread=True, exclusive=True, group="ports")
    def action_rescan(self) -> None:
        choices = self.app.backend.ports()
        self.app.call_later_safe(self._show_ports, choices)

    def _show_ports(self, choices: list[PortChoice]) -> None:
        self.choices = list(choices)
        options = self.query_one("#port-list", OptionList)
        options.clear_options()
        options.add_options(
            [Option(f"{p.label}  {p.detail}".rstrip(), id=p.port) for p in self.choices]
        )
        current = self.app.state.connection.port or self.app._port
        index = next((i for i, p in enumerate(self.choices) if p.port == current), 0)
        if self.choices:
            options.highlighted = index

    def selected_port(self) -> str | None:
        options = self.query_one("#port-list", OptionList)
        i = options.highlighted
        return self.choices[i].port if i is not None and 0 <= i < len(self.choices) else None

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        self.action_connect()

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        state = self.app.state
        if action == "connect":
            return None if state.connection.status in ("connected", "connecting") else True
        if action == "disconnect":
            return True if state.connected and not state.job_active else None
        return True

    def action_connect(self) -> None:
        port = self.selected_port()
        if port is None or self.app.state.connection.status in ("connected", "connecting"):
            return
        try:
            baud = int(self.query_one("#baud-input", Input).value)
        except ValueError:
            self.app.notify("baud must be an integer", severity="error")
            return
        self.app.controller.connect(port, baud)

    def action_disconnect(self) -> None:
        if self.app.state.connected and not self.app.state.job_active:
            self.app.controller.disconnect()
