"""The diagnosis screen: run the workflow on a session, show verdict, where, and the gap."""

from __future__ import annotations

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.widgets import DataTable, Input, Label

from cdprhost.tui.screens.base import AppScreen
from cdprhost.tui.state import DiagnoseView, UiState
from cdprhost.tui.widgets.gap_plot import GapPlot
from cdprhost.tui.widgets.show import show_text

VERDICT_STYLE = {
    "named": "bold green",
    "none": "bold cyan",
    "ambiguous": "bold yellow",
    "unexplained": "bold red",
}


def _opt(v: float | None, fmt: str) -> str:
    return "" if v is None else format(v, fmt)


def verdict_text(view: DiagnoseView) -> Text:
    if view.running:
        return Text(f"diagnosing {view.session_dir} ...", style="cyan")
    if view.error:
        return Text(f"cannot diagnose {view.session_dir}: {view.error}", style="bold red")
    d = view.result
    if d is None:
        return Text("type a session folder and press Enter", style="dim")
    out = Text.assemble(("verdict ", "bold"), (d.verdict, VERDICT_STYLE.get(d.verdict, "bold")))
    if d.effect:
        out.append(f"  effect {d.effect}", style="bold")
    out.append("\nheld-out RMS ")
    out.append(f"{d.heldout_rms_before_mm:.3f}", style="red")
    out.append(" → ")
    out.append(f"{d.heldout_rms_after_mm:.3f} mm", style="green")
    out.append(f"   noise floor {d.noise_floor_mm:.3f} mm", style="cyan")
    if d.where:
        out.append(f"\nwhere: {d.where}")
    if d.parameters:
        out.append("\n" + "   ".join(f"{k} = {v}" for k, v in d.parameters), style="dim")
    return out


class DiagnoseScreen(AppScreen):
    MODE = "diagnose"
    AUTO_FOCUS = "#candidates"
    BINDINGS = [
        Binding("e", "edit", "Session"),
        Binding(
            "w",
            "write_profile",
            "Write profile",
            tooltip="The profile with the named effect added (asked first; a shipped profile "
            "is never rewritten)",
        ),
        Binding("escape", "leave_input", "Back", show=False),
    ]

    def __init__(self) -> None:
        super().__init__(id="diagnose-screen")

    def compose_body(self) -> ComposeResult:
        with Horizontal(id="diag-row"):
            yield Label("session ")
            yield Input(
                placeholder="calibration session folder, Enter to diagnose",
                compact=True,
                id="diag-session",
            )
        yield Label(id="diag-verdict")
        yield DataTable(id="candidates", cursor_type="row", zebra_stripes=True)
        yield GapPlot(id="gap")

    def on_mount(self) -> None:
        table = self.query_one("#candidates", DataTable)
        for name, width in (
            ("candidate", 18),
            ("p value", 10),
            ("ΔBIC", 10),
            ("held-out RMS mm", 16),
        ):
            table.add_column(name, width=width)
        super().on_mount()

    def render_state(self, state: UiState) -> None:
        view = state.diagnose
        show_text(self.query_one("#diag-verdict", Label), verdict_text(view), layout=True)
        table = self.query_one("#candidates", DataTable)
        result = view.result
        if getattr(table, "_shown", None) is not result:
            table.clear()
            for c in result.candidates if result else ():
                table.add_row(
                    c.name,
                    _opt(c.p_value, ".3g"),
                    _opt(c.delta_bic, ".1f"),
                    _opt(c.heldout_rms_mm, ".4f"),
                )
            table._shown = result  # type: ignore[attr-defined]
        gap = self.query_one(GapPlot)
        if result is None:
            gap.show((), (), 0.0)
        else:
            gap.show(result.per_pose_before_mm, result.per_pose_after_mm, result.noise_floor_mm)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action == "write_profile":
            d = self.app.state.diagnose
            return d.result is not None and d.result.verdict == "named" and not d.running
        return True

    def why_not(self, action: str) -> str:
        if action == "write_profile":
            return "only after a diagnosis that names an effect"
        return super().why_not(action)

    def action_write_profile(self) -> None:
        if self.check_action("write_profile", ()):
            self.app.controller.write_diagnosed_profile()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.action_run()

    def action_edit(self) -> None:
        self.query_one("#diag-session", Input).focus()

    def action_leave_input(self) -> None:
        self.query_one("#candidates").focus()

    def action_run(self) -> None:
        session = self.query_one("#diag-session", Input).value.strip()
        if not session or self.app.state.diagnose.running:
            return
        self.query_one("#candidates").focus()
        self.app.controller.diagnose(session)
