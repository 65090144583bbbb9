"""The jog screen: step the effector, seeing first whether the target is feasible."""

from __future__ import annotations

from typing import Any

from rich.text import Text
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.dom import DOMNode
from textual.widgets import Input, Label

from cdprhost.tui.control.jog import STEPS_MM, static_tensions
from cdprhost.tui.keys import key_for
from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.state import UiState, live_position, shown_temperatures
from cdprhost.tui.widgets.position_panel import PositionPanel
from cdprhost.tui.widgets.show import show_text
from cdprhost.tui.widgets.temperature_graph import TemperatureGraph
from cdprhost.tui.widgets.tension_bars import TensionBars


def keys_help(app: App[Any], screen: DOMNode) -> str:
    """The jog keys as the help screen names them (taken from the bindings)."""

    def pair(axis: str) -> str:
        minus = key_for(app, screen, f"jog('{axis}', -1)")
        plus = key_for(app, screen, f"jog('{axis}', 1)")
        return f"{minus}{plus}" if len(minus) == len(plus) == 1 else f"{minus}/{plus}"

    first, last = (
        key_for(app, screen, "step(0)"),
        key_for(app, screen, f"step({len(STEPS_MM) - 1})"),
    )
    go, clear, keys = (
        key_for(app, n, a) for n, a in ((screen, "go"), (screen, "clear"), (app, "help"))
    )
    return (
        f"{pair('x')} x   {pair('y')} y   {pair('z')} z   {first}-{last} step   "
        f"{go} move   {clear} clear   {keys} all keys"
    )


def target_text(state: UiState) -> Text:
    jog = state.jog
    out = Text("target  ", style="bold")
    if jog is None:
        return out.append("none: press an arrow key", style="dim")
    out.append("({:.2f}, {:.2f}, {:.2f}) mm  ".format(*jog.target))
    if jog.ok:
        return out.append("feasible · Enter moves", style="bold green")
    return out.append(f"NOT feasible · {jog.reason}", style="bold red")


class JogScreen(AppScreen):
    MODE = "jog"
    AUTO_FOCUS = ""
    BINDINGS = [
        Binding("left", "jog('x', -1)", "x-", show=False),
        Binding("right", "jog('x', 1)", "x+", show=False),
        Binding("down", "jog('y', -1)", "y-", show=False),
        Binding("up", "jog('y', 1)", "y+", show=False),
        Binding("pagedown", "jog('z', -1)", "z-", show=False),
        Binding("pageup", "jog('z', 1)", "z+", show=False),
        *(
            Binding(str(i + 1), f"step({i})", f"{s:g} mm", show=False)
            for i, s in enumerate(STEPS_MM)
        ),
        Binding("enter", "go", "Move"),
        Binding("escape", "clear", "Clear", show=False),
        Binding("h", "home", "Home"),
        Binding("m", "motors_off", "Motors off"),
        Binding("t", "heaters", "Set heaters"),
        Binding("e", "edit_heaters", "Heater targets", show=False),
    ]

    def __init__(self) -> None:
        super().__init__(id="jog-screen")
        self.step_index = 1

    def compose_body(self) -> ComposeResult:
        backend = self.app.backend
        statics = backend.model.statics
        bed = backend.profile.build_volume.bed_origin
        with Horizontal(id="jog-top"):
            yield PositionPanel((float(bed[0]), float(bed[1]), float(bed[2])), id="jog-position")
            yield TensionBars(statics.t_min, statics.t_max, id="jog-tensions")
        yield Label(id="jog-step")
        yield Label(id="jog-target")
        yield Label(id="jog-help")
        yield Label(id="jog-busy")
        with Horizontal(id="heater-row"):
            yield Label("hotend °C ")
            yield Input("0", type="number", compact=True, id="hotend-input")
            yield Label(" bed °C ")
            yield Input("0", type="number", compact=True, id="bed-input")
            yield Label(id="heater-hint", classes="hint")
        yield TemperatureGraph(id="jog-temperatures")

    def on_mount(self) -> None:
        self.query_one("#jog-help", Label).update(keys_help(self.app, self))
        edit, apply = key_for(self.app, self, "edit_heaters"), key_for(self.app, self, "heaters")
        self.query_one("#heater-hint", Label).update(f"  {edit} edits, Enter or {apply} sets both")
        super().on_mount()

    def render_state(self, state: UiState) -> None:
        position, sliders, _ = live_position(state)
        steps = state.device.steps if state.device else None
        self.query_one(PositionPanel).show(position, sliders, steps)
        show_text(
            self.query_one("#jog-step", Label),
            Text.assemble(
                ("step  ", "bold"),
                *(
                    (f" {s:g} ", "reverse" if i == self.step_index else "dim")
                    for i, s in enumerate(STEPS_MM)
                ),
                ("  mm", "dim"),
            ),
        )
        show_text(self.query_one("#jog-target", Label), target_text(state), layout=True)
        busy = state.busy or ("print running: jog disabled" if state.job_active else "")
        if not state.connected:
            busy = "not connected"
        show_text(self.query_one("#jog-busy", Label), Text(busy, style="yellow"), layout=True)
        target = state.jog.target if state.jog is not None else position
        title = (
            "tension at target (predicted)" if state.jog is not None else "tension here (predicted)"
        )
        self.query_one(TensionBars).show(static_tensions(self.app.backend.model, target), title)
        self._render_temperatures(state)

    def render_tick(self, state: UiState) -> None:
        self._render_temperatures(state)

    def _render_temperatures(self, state: UiState) -> None:
        t = shown_temperatures(state, self.app.clock())
        self.query_one(TemperatureGraph).show(t.current, t.targets, t.history, t.stale_s)

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.action_heaters()

    def action_edit_heaters(self) -> None:
        self.query_one("#hotend-input", Input).focus()

    # ------------------------------------------------------------ actions
    def _can_move(self) -> bool:
        s = self.app.state
        return s.connected and not s.job_active and not s.busy

    def why_not(self, action: str) -> str:
        jog = self.app.state.jog
        if action == "go" and self._can_move():
            return "no target: an arrow key sets one" if jog is None else f"target {jog.reason}"
        return super().why_not(action)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in ("go", "home", "motors_off", "heaters"):
            if not self._can_move():
                return None
            if action == "go":
                return True if self.app.state.jog is not None and self.app.state.jog.ok else None
        return True

    def action_jog(self, axis: str, sign: int) -> None:
        if self._can_move():
            self.app.controller.preview_jog(axis, sign * STEPS_MM[self.step_index])

    def action_step(self, index: int) -> None:
        self.step_index = index
        self.render_state(self.app.state)

    def action_go(self) -> None:
        if self._can_move():
            self.app.controller.jog_go()

    def action_clear(self) -> None:
        self.set_focus(None)
        self.app.controller.clear_jog()

    def action_home(self) -> None:
        if self._can_move():
            self.app.confirm(
                "Home: drive the three modules to their endstops?", self.app.controller.home
            )

    def action_motors_off(self) -> None:
        if self._can_move():
            self.app.controller.motors_off()

    def action_heaters(self) -> None:
        if not self._can_move():
            return
        try:
            hotend = float(self.query_one("#hotend-input", Input).value or 0)
            bed = float(self.query_one("#bed-input", Input).value or 0)
        except ValueError:
            self.app.notify("heater targets must be numbers", severity="error")
            return
        heaters = self.app.backend.profile.heaters
        if not (0 <= hotend <= heaters.hotend_max_c and 0 <= bed <= heaters.bed_max_c):
            self.app.notify(
                f"targets must be within 0-{heaters.hotend_max_c:g} / 0-{heaters.bed_max_c:g} °C",
                severity="error",
            )
            return
        self.set_focus(None)
        self.app.controller.set_heaters(hotend, bed)
