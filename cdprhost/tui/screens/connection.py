"""The link screen: pick a listed port (serial adapters, pseudo-terminals, the embedded
simulated device) or type one (a device path or a pyserial URL), connect, see the device
and the link."""

from __future__ import annotations

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import DataTable, Input, Label, OptionList
from textual.widgets.option_list import Option

from cdprhost.tui.control.backend import EMBEDDED
from cdprhost.tui.control.views import PortChoice
from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.state import UiState
from cdprhost.tui.widgets.show import show_text

SIMULATOR = "embedded simulated device (no hardware)"
RESCAN_S = 3.0


def health_text(state: UiState) -> Text:
    h = state.job.link if state.job_active else state.connection.health
    out = Text("health  ", style="bold")
    if h is None:
        return out.append("--", style="dim")
    bad = h.bad_frames or h.retransmits
    out.append(
        f"retx {h.retransmits} · bad {h.bad_frames} · naks {h.naks}",
        style="yellow" if bad else "green",
    )
    return out


def port_name(port: str) -> str:
    return SIMULATOR if port == EMBEDDED else port


def status_text(state: UiState) -> Text:
    c = state.connection
    style = {"connected": "bold green", "connecting": "cyan", "error": "bold red"}.get(
        c.status, "dim"
    )
    out = Text.assemble(("status  ", "bold"), (c.status, style))
    if c.port:
        out.append(f"\n{port_name(c.port)}")
        if not c.simulated:
            out.append(f" @ {c.baud} baud")
    if c.simulated and c.status in ("connected", "connecting"):
        out.append("\nSIMULATOR: no machine moves", style="bold reverse yellow")
    if c.error:
        out.append(f"\n{c.error}", style="red")
    return out


def port_option(p: PortChoice) -> Option:
    text = Text(p.label, style="bold" if p.simulated else "")
    if p.detail:
        text.append(f"  {p.detail}", style="dim")
    return Option(text, id=p.port)


class ConnectionScreen(AppScreen):
    MODE = "connection"
    AUTO_FOCUS = "#port-list"
    BINDINGS = [
        Binding("c", "connect", "Connect", tooltip="The highlighted port (Enter also connects)"),
        Binding("t", "type_port", "Type a port", tooltip="A device path or a pyserial URL"),
        Binding("d", "disconnect", "Disconnect"),
        Binding("r", "rescan", "Rescan ports"),
        Binding("escape", "leave_input", "Back", show=False),
    ]

    def __init__(self) -> None:
        super().__init__(id="connection-screen")
        self.choices: list[PortChoice] = []
        self._scanned = float("-inf")

    def compose_body(self) -> ComposeResult:
        with Horizontal(id="conn-top"):
            with Vertical(id="conn-ports"):
                yield Label("Ports (Enter connects)", classes="section-title")
                yield OptionList(id="port-list", compact=True)
                with Horizontal(id="typed-row"):
                    yield Label("port ")
                    yield Input(
                        placeholder="/dev/ttyACM0, /dev/pts/3, socket://host:port ... Enter",
                        compact=True,
                        id="port-input",
                    )
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
        show_text(self.query_one("#conn-status", Label), status_text(state), layout=True)
        show_text(self.query_one("#conn-health", Label), health_text(state), layout=True)
        table = self.query_one("#identity", DataTable)
        if getattr(table, "_shown", None) != c.identity:
            table.clear()
            for key, value in c.identity:
                table.add_row(key, value)
            table._shown = c.identity  # type: ignore[attr-defined]

    def on_screen_resume(self) -> None:
        super().on_screen_resume()
        self.action_rescan()

    def render_tick(self, state: UiState) -> None:
        """The port list follows what is plugged in (scanned every ``RESCAN_S`` here)."""
        if self.app.clock() - self._scanned >= RESCAN_S:
            self.action_rescan()

    def action_rescan(self) -> None:
        self._scanned = self.app.clock()
        self._scan()

    @work(thread=True, exclusive=True, group="ports")
    def _scan(self) -> None:
        choices = self.app.backend.ports()
        self.app.call_later_safe(self._show_ports, choices)

    def _show_ports(self, choices: list[PortChoice]) -> None:
        if list(choices) == self.choices:
            return  # nothing plugged or unplugged: the highlight stays
        keep = self.selected_port()
        self.choices = list(choices)
        options = self.query_one("#port-list", OptionList)
        options.clear_options()
        options.add_options([port_option(p) for p in self.choices])
        current = keep or self.app.state.connection.port or self.app._port
        index = next((i for i, p in enumerate(self.choices) if p.port == current), 0)
        if self.choices:
            options.highlighted = index

    def selected_port(self) -> str | None:
        options = self.query_one("#port-list", OptionList)
        i = options.highlighted
        return self.choices[i].port if i is not None and 0 <= i < len(self.choices) else None

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        self.action_connect()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        if event.input.id == "port-input" and event.value.strip():
            self._connect(event.value.strip())
        self.query_one("#port-list").focus()

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        state = self.app.state
        if action == "connect":
            return None if state.connection.status == "connecting" or state.job_active else True
        if action == "disconnect":
            return True if state.connected and not state.job_active else None
        return True

    def action_connect(self) -> None:
        port = self.selected_port()
        if port is not None:
            self._connect(port)

    def _connect(self, port: str) -> None:
        state = self.app.state
        if state.connection.status == "connecting" or state.job_active:
            return
        if state.connected and state.connection.port == port:
            return
        try:
            baud = int(self.query_one("#baud-input", Input).value)
        except ValueError:
            self.app.notify("baud must be an integer", severity="error")
            return
        self.app.notify(
            f"connecting to {port_name(port)}"
            + (": nothing real will move" if port == EMBEDDED else f" at {baud} baud"),
            title="link",
            severity="warning" if port == EMBEDDED else "information",
        )
        self.app.controller.connect(port, baud)

    def action_type_port(self) -> None:
        self.query_one("#port-input", Input).focus()

    def action_leave_input(self) -> None:
        self.query_one("#port-list").focus()

    def action_disconnect(self) -> None:
        if self.app.state.connected and not self.app.state.job_active:
            self.app.controller.disconnect()
